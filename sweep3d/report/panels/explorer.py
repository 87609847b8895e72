"""Explorer (after 3DB's dashboard): any two parameters as heat-map axes, others as sliders or pooled.

The page gets every result as compact columnar JSON (each parameter's level per result, the
outcome, the top-1 prediction and a thumbnail index); ``static/explorer.js`` computes the heat
map and the gallery of a clicked cell in the browser.
"""

from __future__ import annotations

import json
from typing import Any

from sweep3d.report.figures import ACCURACY_COLORSCALE, layout_json
from sweep3d.report.panel import PanelInputs
from sweep3d.report.results import ResultTable
from sweep3d.stages.aggregate.views import SCENE_COLUMNS

GALLERY_LIMIT = 60  # tiles shown for a clicked cell (wrong ones first)


def build(inputs: PanelInputs) -> dict[str, Any]:
    """The explorer's JSON payload (see :func:`payload`)."""
    return {"json": json.dumps(payload(inputs), separators=(",", ":"), ensure_ascii=False),
            "results": len(inputs.table)}


def payload(inputs: PanelInputs) -> dict[str, Any]:
    """Every result, column by column.

    Keys: ``params`` (name, level labels, binned) of the parameters shown; ``level`` (one list
    per parameter: each result's level); ``outcome`` (0 wrong, 1 correct, 2 invalid); ``pred``
    (index into ``preds``, -1 for none); ``thumb`` (index into the page's thumbnails); ``job``;
    ``defaults`` (the parameters first on the x and y axes, -1 for none); ``limit`` (gallery size);
    ``colorscale`` and ``layout`` (the report's plot style) for the heat map.
    Rows come wrong-first, highest loss first (see :mod:`sweep3d.report.results`).
    """
    table = inputs.table
    shown = [i for i, p in enumerate(table.parameters) if p.varies or p.name in SCENE_COLUMNS]
    params = [table.parameters[i] for i in shown]
    preds = sorted({p for p in table.prediction if p is not None})
    pred_index = {p: i for i, p in enumerate(preds)}
    return {
        "params": [{"name": p.name, "labels": p.labels, "binned": p.binned} for p in params],
        "level": [table.levels[i].tolist() for i in shown],
        "outcome": table.outcome.tolist(),
        "pred": [pred_index.get(p, -1) if p is not None else -1 for p in table.prediction],
        "preds": preds,
        "thumb": [inputs.thumbs.want(key) for key in table.image_key],
        "job": table.job.tolist(),
        "defaults": default_axes(table, shown),
        "limit": GALLERY_LIMIT,
        "colorscale": ACCURACY_COLORSCALE,
        "layout": layout_json(margin={"l": 16, "r": 16, "t": 16, "b": 48}),
    }


def default_axes(table: ResultTable, shown: list[int]) -> dict[str, int]:
    """First view: object down, environment across (or the first control that varies)."""
    names = [table.parameters[i].name for i in shown]
    varies = [table.parameters[i].varies for i in shown]
    y = names.index("object") if "object" in names else -1
    across = [i for i, name in enumerate(names) if varies[i] and i != y]
    environment = names.index("environment") if "environment" in names else -1
    if environment >= 0 and varies[environment]:
        x = environment
    elif across:
        x = across[0]
    else:
        x = environment if environment != y else -1
    return {"x": x, "y": y}
