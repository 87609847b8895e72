"""Failure modes: the control regions where the model is significantly worse than overall.

A region is one level of a parameter, or a pair of levels of two parameters (listed only when
the pair is confidently worse than each level alone). Regions need ``min_count`` counted results
and an accuracy below the overall one; they are ranked by the upper bound of the 95 % Wilson
interval, so a small region must be very bad to rank above a large, merely bad one. A region is
*significant* when a one-sided exact binomial test of its results against the overall accuracy
holds after Holm's adjustment over every region tested (``p_holm`` < 0.05). The table and the
figure show the significant regions; the others are listed apart, greyed, without examples. The
list comes from the ``failure_modes`` SQL macro (see :mod:`sweep3d.stages.aggregate.views`).
"""

from __future__ import annotations

from typing import Any

from sweep3d.report.figures import (
    ACCURACY_AXIS,
    COLORS,
    Figure,
    interval,
    layout,
    make_figure,
    p_text,
    pct,
    plot_text,
)
from sweep3d.report.panel import PanelInputs

TOP = 12  # regions listed
EXAMPLES = 4  # wrong predictions shown per region


def build(inputs: PanelInputs) -> dict[str, Any]:
    """The ranked significant regions, each with examples, a dot plot of their accuracy and
    interval, and the regions below the overall accuracy that are not significantly below it."""
    sql = f"FROM failure_modes(min_count := {inputs.min_count}) WHERE significant LIMIT {TOP}"
    modes = inputs.rows(sql)
    weak = inputs.rows(f"FROM failure_modes(min_count := {inputs.min_count}) WHERE NOT significant LIMIT {TOP}")
    weak_total = inputs.con.execute(
        f"SELECT count(*) FROM failure_modes(min_count := {inputs.min_count}) WHERE NOT significant").fetchone()[0]
    known = {p.name for p in inputs.parameters}
    rows = []
    for mode in modes:
        terms = _terms(mode)
        where = {parameter: level for parameter, level, _ in terms}
        examples = []
        if set(where) <= known:
            examples = [inputs.tile(row) for row in inputs.results.examples(where, EXAMPLES)]
        rows.append({**_row(mode), "examples": examples})
    return {
        "modes": rows,
        "weak": [_row(mode) for mode in weak],
        "weak_total": weak_total,
        "min_count": inputs.min_count,
        "overall": pct(inputs.summary.accuracy, 0),
        "figure": _figure(modes, inputs.summary.accuracy, sql) if modes else None,
    }


def _terms(mode: dict[str, Any]) -> list[tuple[str, int, str]]:
    """(parameter, level, label) of each of the region's one or two values."""
    return [(mode[f"parameter_{s}"], mode[f"level_{s}"], mode[f"label_{s}"]) for s in "ab"
            if mode[f"parameter_{s}"] is not None]


def _row(mode: dict[str, Any]) -> dict[str, Any]:
    """A table row: the region's values, accuracy, interval, counts and Holm-adjusted p-value."""
    return {"terms": [(parameter, label) for parameter, _, label in _terms(mode)],
            "accuracy": pct(mode["accuracy"], 0), "interval": interval(mode["wilson_low"], mode["wilson_high"]),
            "wrong": mode["n"] - mode["n_correct"], "count": mode["n"], "p_holm": p_text(mode["p_holm"])}


def _figure(modes: list[dict[str, Any]], overall: float | None, sql: str) -> Figure:
    """Accuracy of each region (dot) with its Wilson interval (bar), worst at the top."""
    labels = [f"{i + 1}. " + plot_text(m["region"]) for i, m in enumerate(modes)]
    trace = {
        "type": "scatter", "mode": "markers", "y": labels, "x": [m["accuracy"] for m in modes],
        "marker": {"color": COLORS["wrong"], "size": 9},
        "error_x": {"type": "data", "symmetric": False, "color": COLORS["muted"], "thickness": 1.5, "width": 4,
                    "array": [m["wilson_high"] - m["accuracy"] for m in modes],
                    "arrayminus": [m["accuracy"] - m["wilson_low"] for m in modes]},
        "customdata": [[m["n"], m["n"] - m["n_correct"], m["wilson_low"], m["wilson_high"]] for m in modes],
        "hovertemplate": "%{y}<br>accuracy %{x:.1%} (95% CI %{customdata[2]:.0%}–%{customdata[3]:.0%})"
                         "<br>%{customdata[1]} wrong of %{customdata[0]}<extra></extra>",
        "showlegend": False,
    }
    shapes = []
    if overall is not None:
        shapes.append({"type": "line", "xref": "x", "yref": "paper", "x0": overall, "x1": overall, "y0": 0, "y1": 1,
                       "line": {"color": COLORS["bar"], "dash": "dot", "width": 1.5}})
    figure_layout = layout(
        height=90 + 30 * len(modes), margin={"l": 16, "r": 16, "t": 28, "b": 40}, shapes=shapes,
        xaxis={**ACCURACY_AXIS, "title": {"text": "accuracy (95% Wilson interval); dotted: overall"}},
        yaxis={"type": "category", "autorange": "reversed", "automargin": True},
    )
    return make_figure("fig-failure-modes", [trace], figure_layout, sql)
