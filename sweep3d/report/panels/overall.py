"""Overall accuracy: one stacked bar of correct, wrong and invalid predictions."""

from __future__ import annotations

from typing import Any

from sweep3d.report.figures import COLORS, layout, make_figure, pct
from sweep3d.report.panel import PanelInputs


def build(inputs: PanelInputs) -> dict[str, Any]:
    """The outcome bar and the overall accuracy."""
    summary = inputs.summary
    wrong = summary.evaluated - summary.invalid - summary.correct
    traces = [
        {"type": "bar", "name": name, "y": ["jobs"], "x": [count], "orientation": "h",
         "marker": {"color": COLORS[name]}, "text": [count] if count else [""], "textposition": "inside",
         "hovertemplate": f"{name}: %{{x}}<extra></extra>"}
        for name, count in (("correct", summary.correct), ("wrong", wrong), ("invalid", summary.invalid))
    ]
    figure_layout = layout(
        barmode="stack", height=150, margin={"l": 16, "r": 16, "t": 8, "b": 32},
        legend={"orientation": "h", "y": -0.35, "x": 0, "traceorder": "normal"}, yaxis={"visible": False},
        xaxis={"title": None, "range": [0, max(summary.evaluated, 1)]},
    )
    query = ("SELECT count(*) FILTER (WHERE valid AND correct) AS correct, "
             "count(*) FILTER (WHERE valid AND NOT correct) AS wrong, count(*) FILTER (WHERE NOT valid) AS invalid "
             "FROM results")
    return {"accuracy": pct(summary.accuracy), "figure": make_figure("fig-outcomes", traces, figure_layout, query)}
