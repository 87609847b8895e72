"""Overall accuracy: one stacked bar of correct, wrong and invalid predictions, and the jobs that
were not evaluable (out of frame or hidden) when there are any: counted apart, never as wrong."""

from __future__ import annotations

from typing import Any

from sweep3d.report.figures import COLORS, layout, make_figure, pct
from sweep3d.report.panel import PanelInputs

NOT_EVALUABLE_COLOR = "#c9ccd1"


def build(inputs: PanelInputs) -> dict[str, Any]:
    """The outcome bar and the overall accuracy."""
    summary = inputs.summary
    segments = [("correct", summary.correct, COLORS["correct"]), ("wrong", summary.wrong, COLORS["wrong"]),
                ("invalid", summary.invalid, COLORS["invalid"])]
    if summary.not_evaluable:
        segments.append(("not evaluable", summary.not_evaluable, NOT_EVALUABLE_COLOR))
    traces = [
        {"type": "bar", "name": name, "y": ["jobs"], "x": [count], "orientation": "h",
         "marker": {"color": color}, "text": [count] if count else [""], "textposition": "inside",
         "hovertemplate": f"{name}: %{{x}}<extra></extra>"}
        for name, count, color in segments
    ]
    figure_layout = layout(
        barmode="stack", height=150, margin={"l": 16, "r": 16, "t": 8, "b": 32},
        legend={"orientation": "h", "y": -0.35, "x": 0, "traceorder": "normal"}, yaxis={"visible": False},
        xaxis={"title": None, "range": [0, max(sum(count for _, count, _ in segments), 1)]},
    )
    if summary.not_evaluable:
        query = ("SELECT count(*) FILTER (WHERE counted AND correct) AS correct, "
                 "count(*) FILTER (WHERE counted AND NOT correct) AS wrong, "
                 "count(*) FILTER (WHERE NOT valid AND evaluable IS NOT FALSE) AS invalid, "
                 "(SELECT sum(n) FROM not_evaluable) AS not_evaluable FROM results")
    else:
        query = ("SELECT count(*) FILTER (WHERE valid AND correct) AS correct, "
                 "count(*) FILTER (WHERE valid AND NOT correct) AS wrong, count(*) FILTER (WHERE NOT valid) AS invalid "
                 "FROM results")
    return {"accuracy": pct(summary.accuracy), "figure": make_figure("fig-outcomes", traces, figure_layout, query)}
