"""Explorer (after 3DB's dashboard): any two parameters as heat-map axes, others as sliders or pooled.

Besides the spec's parameters, the results' measures are axes too, binned as ``control_accuracy``
bins them: the object's visible fraction (truth passes), the classifier's margin and the IoU
(:mod:`sweep3d.results.measures`): accuracy against how much of the object shows is one
choice of axis.

The page carries counts, not rows: the non-empty cells of the contingency table over every
parameter shown (per combination of levels: valid results, correct ones, all results; levels as
in ``control_levels``). ``static/explorer.js`` sums them into any heat map (two parameters as
axes, sliders fixing others to one level, the rest pooled), so every number it shows is exact,
and the page grows with the numbers of levels (at most min(results, Π levels) cells), not with
the results. Where that table would pass :data:`MAX_CELLS` cells (many parameters with many
levels), the page carries one table per pair of parameters instead: any two as axes stay exact,
sliders are switched off (the others are pooled), and the panel says so.

Images are a sample (:meth:`~sweep3d.report.reading.Results.sample`) filling what the other
panels leave of the page's image budget: :data:`FIRST_VIEW_IMAGES` per cell of the first view,
then rounds of one per cell (of the joint table, or of every pair's), failures first. A clicked
cell shows its sampled images, says how many it holds beyond them, and gives the ``sweep3d
query`` that lists them all.
"""

from __future__ import annotations

import itertools
import json
from typing import Any

from sweep3d.report.figures import ACCURACY_COLORSCALE, layout_json
from sweep3d.report.panel import PanelInputs
from sweep3d.report.reading import Parameter, ResultRow
from sweep3d.results import SCENE_COLUMNS

GALLERY_LIMIT = 60  # tiles shown for a clicked cell (wrong ones first)
MAX_CELLS = 200_000  # cells of the joint table at most; beyond, pair tables and no sliders
FIRST_VIEW_IMAGES = 6  # sampled images per cell of the first view, before one per cell of every view


def build(inputs: PanelInputs, max_cells: int = MAX_CELLS) -> dict[str, Any]:
    """The explorer's JSON payload (see :func:`payload`) and what the template says about it."""
    data = payload(inputs, max_cells)
    return {"json": json.dumps(data, separators=(",", ":"), ensure_ascii=False), "mode": data["mode"],
            "cells": data["cells"], "max_cells": max_cells, "images": len(data["sample"]["job"]),
            "gated": data["gated"]}


def payload(inputs: PanelInputs, max_cells: int = MAX_CELLS) -> dict[str, Any]:
    """What the page's explorer draws from.

    Keys: ``params`` (name, level labels, binned) of the parameters shown; ``mode`` (``joint``:
    one table over all of them; ``pairs``: one per pair, no sliders); ``cells`` (non-empty cells
    of the joint table); ``tables`` (each: ``params``, indices into ``params``, and the columns
    of :meth:`~sweep3d.report.reading.Results.counts`); ``sample`` (the results whose images the
    page embeds, most telling first: ``level`` per parameter, ``outcome``, ``pred`` (index into
    ``preds``, -1 for none), ``why`` (index into ``whys``: a box or mask task's reason for a
    failure, ``wrong box · IoU 0.32``; -1 for none), ``thumb`` (index into the page's thumbnails), ``job``); ``defaults``
    (the parameters first on the x and y axes, -1 for none); ``limit`` (gallery size); ``query``
    (the spec and the ORDER BY of the gallery's SQL); ``colorscale`` and ``layout``; ``gated``
    (some jobs are not evaluable: the counts leave them out, and the page says "counted").
    """
    results = inputs.results
    axes = results.parameters + getattr(results, "measures", [])  # measures (visible fraction, margin, IoU) last
    shown = [i for i, p in enumerate(axes) if p.varies or p.name in SCENE_COLUMNS]
    params = [axes[i] for i in shown]
    defaults = default_axes(params)
    cells = results.cells(shown)
    groups = [list(range(len(shown)))] if cells <= max_cells else pairs(len(shown))
    first = [shown[defaults[axis]] for axis in ("x", "y") if defaults[axis] >= 0]
    # images are sampled per cell of the parameters (a measure's bins would thin every cell's share)
    measures = len(results.parameters)
    sampled = [[shown[p] for p in group if shown[p] < measures] for group in groups]
    jobs = results.sample([g for g in sampled if g], first, FIRST_VIEW_IMAGES, inputs.thumbs.remaining)
    return {
        "params": [{"name": p.name, "labels": p.labels, "binned": p.binned} for p in params],
        "mode": "joint" if cells <= max_cells else "pairs",
        "cells": cells,
        "tables": [{"params": group, **results.counts([shown[p] for p in group])} for group in groups],
        **sample(inputs, results.rows(jobs), shown),
        "defaults": defaults,
        "limit": GALLERY_LIMIT,
        "query": {"spec": str(inputs.loaded.path), "order": results.example_order_sql},
        "colorscale": ACCURACY_COLORSCALE,
        "layout": layout_json(margin={"l": 16, "r": 16, "t": 16, "b": 48}),
        "gated": inputs.summary.not_evaluable > 0,
    }


def pairs(count: int) -> list[list[int]]:
    """Every pair of ``count`` parameters (the one parameter alone when there is only one)."""
    return [list(pair) for pair in itertools.combinations(range(count), 2)] or [list(range(count))]


def sample(inputs: PanelInputs, rows: list[ResultRow], shown: list[int]) -> dict[str, Any]:
    """The sampled results column by column (``sample``) and their predictions' names (``preds``)."""
    preds = sorted({r.prediction for r in rows if r.prediction is not None})
    index = {p: i for i, p in enumerate(preds)}
    whys = sorted({r.why for r in rows if r.why is not None})
    why_index = {w: i for i, w in enumerate(whys)}
    return {"sample": {
        "level": [[r.levels[i] for r in rows] for i in shown],
        "outcome": [r.outcome for r in rows],
        "pred": [index.get(r.prediction, -1) for r in rows],
        "why": [why_index.get(r.why, -1) for r in rows],
        "thumb": [inputs.thumbs.want(r.image_key) for r in rows],
        "job": [r.job for r in rows],
    }, "preds": preds, "whys": whys}


def default_axes(params: list[Parameter]) -> dict[str, int]:
    """First view: object down, environment across (or the first control that varies)."""
    names = [p.name for p in params]
    y = names.index("object") if "object" in names else -1
    across = [i for i, p in enumerate(params) if p.varies and i != y]
    environment = names.index("environment") if "environment" in names else -1
    if environment >= 0 and params[environment].varies:
        x = environment
    elif across:
        x = across[0]
    else:
        x = environment if environment != y else -1
    return {"x": x, "y": y}

