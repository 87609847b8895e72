"""Not evaluable: the jobs no accuracy counts, and why (out of frame, fully occluded, or too little of the
object visible).

A model cannot be right or wrong about an object it was not shown, so these jobs are counted
apart, never as failures. Every number comes from the ``not_evaluable`` view (see
:mod:`sweep3d.results.task_views`); the panel is left out when there are none.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from sweep3d.report.figures import Figure, layout, make_figure, pct, plot_text
from sweep3d.report.panel import PanelInputs
from sweep3d.results import HIDDEN, OCCLUDED, OUT_OF_FRAME, has_view

REASONS = (OUT_OF_FRAME, OCCLUDED, HIDDEN)
REASON_COLORS = {OUT_OF_FRAME: "#9aa0a6", OCCLUDED: "#8c6d5a", HIDDEN: "#dd8452"}


def build(inputs: PanelInputs) -> dict[str, Any] | None:
    """Totals per reason, a row per object, and a stacked bar of both; None when every job is evaluable."""
    if not has_view(inputs.con, "not_evaluable"):
        return None
    rows = inputs.rows("SELECT object, reason, n, object_jobs, share, min_visible FROM not_evaluable")
    if not rows:
        return None
    totals = {reason: n for reason, n in inputs.con.execute(
        "SELECT reason, sum(n)::BIGINT FROM not_evaluable GROUP BY reason").fetchall()}
    per_object: dict[str, dict[str, Any]] = defaultdict(dict)
    for row in rows:
        entry = per_object[row["object"]]
        entry["jobs"] = row["object_jobs"]
        entry[row["reason"]] = {"n": row["n"], "share": pct(row["share"])}
    thresholds = {row["min_visible"] for row in rows if row["min_visible"] is not None}
    return {
        "total": sum(totals.values()),
        "jobs": inputs.summary.jobs,
        "reasons": [{"reason": r, "n": totals.get(r, 0)} for r in REASONS],
        "min_visible": pct(thresholds.pop(), 0) if thresholds else None,
        "objects": [{"object": name, "jobs": entry["jobs"],
                     "cells": [entry.get(r, {"n": 0, "share": pct(0.0)}) for r in REASONS]}
                    for name, entry in sorted(per_object.items())],
        "figure": _figure(per_object),
    }


def _figure(per_object: dict[str, dict[str, Any]]) -> Figure:
    """Per object, its unevaluable jobs stacked by reason."""
    objects = sorted(per_object)
    traces = [{
        "type": "bar", "orientation": "h", "name": reason, "y": [plot_text(o) for o in objects],
        "x": [per_object[o].get(reason, {"n": 0})["n"] for o in objects], "marker": {"color": REASON_COLORS[reason]},
        "customdata": [per_object[o]["jobs"] for o in objects],
        "hovertemplate": f"%{{y}}: %{{x}} of %{{customdata}} jobs {reason}<extra></extra>",
    } for reason in REASONS]
    figure_layout = layout(
        barmode="stack", height=110 + 28 * len(objects), margin={"l": 16, "r": 16, "t": 16, "b": 40},
        legend={"orientation": "h", "y": 1.02, "yanchor": "bottom"},
        xaxis={"title": {"text": "jobs not evaluable"}, "rangemode": "tozero"},
        yaxis={"type": "category", "autorange": "reversed", "automargin": True},
    )
    return make_figure("fig-not-evaluable", traces, figure_layout, "FROM not_evaluable")
