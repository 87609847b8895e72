"""Boxes and masks: how a localization, detection or segmentation model fails at each control value.

Accuracy alone hides *how* a box or mask task fails, so each value's counted results are split
into correct, wrong class, right class but wrong box (or mask: IoU below ``[evaluator] iou``) and
missed, as stacked bars (from ``outcomes_by_value``); and the IoU with the truth is shown per
object as a box plot of its quantiles (from ``iou_by_object``). Left out for classification.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from sweep3d.report.figures import COLORS, Figure, layout, make_figure, plot_text, title
from sweep3d.report.panel import PanelInputs
from sweep3d.report.reading import Parameter
from sweep3d.results import OUTCOMES, has_view

OUTCOME_STYLE = {"correct": ("correct", COLORS["correct"]), "wrong_class": ("wrong class", COLORS["wrong"]),
                 "wrong_box": ("right class, wrong box", COLORS["interaction"]),
                 "missed": ("missed", COLORS["invalid"])}
SHARE_AXIS = {"range": [0, 1], "tickformat": ".0%", "title": {"text": "share of results"}}


def build(inputs: PanelInputs) -> dict[str, Any] | None:
    """One stacked-bar figure per varying parameter and the IoU box plot; None without box or mask results."""
    has_outcomes, has_iou = (has_view(inputs.con, v) for v in ("outcomes_by_value", "iou_by_object"))
    if not has_outcomes and not has_iou:
        return None
    figures = []
    if has_outcomes:
        levels: dict[str, list[dict[str, Any]]] = defaultdict(list)
        for row in inputs.rows("FROM outcomes_by_value ORDER BY position, level"):
            levels[row["parameter"]].append(row)
        varied = [p for p in inputs.parameters if p.varies and levels[p.name]]
        figures = [_outcome_figure(i, p, levels[p.name]) for i, p in enumerate(varied, 1)]
    iou = _iou_figure(inputs.rows("FROM iou_by_object")) if has_iou else None
    precision = _average_precision(inputs) if has_view(inputs.con, "average_precision") else []
    if not figures and iou is None and not precision:
        return None
    return {"outcomes": figures, "iou": iou, "has_outcomes": has_outcomes, "precision": precision}


def _average_precision(inputs: PanelInputs) -> list[dict[str, Any]]:
    """Detection's COCO average precision per object and their mean (``average_precision``), as
    table rows with percentages; the mean first."""
    def percent(value: Any) -> str:
        return "–" if value is None else f"{100 * value:.1f}"

    return [{"object": r["object"] if r["object"] is not None else "mean over objects", "images": r["images"],
             "ap50": percent(r["ap50"]), "ap75": percent(r["ap75"]), "ap": percent(r["ap"])}
            for r in inputs.rows("FROM average_precision")]


def _outcome_figure(index: int, parameter: Parameter, rows: list[dict[str, Any]]) -> Figure:
    """Shares of each outcome at each level of ``parameter``, stacked to 1."""
    x = list(range(len(rows)))
    labels = [plot_text(r["label"]) for r in rows]
    traces = []
    for outcome in OUTCOMES:
        name, color = OUTCOME_STYLE[outcome]
        traces.append({
            "type": "bar", "name": name, "x": x, "y": [r[f"share_{outcome}"] for r in rows], "text": labels,
            "textposition": "none", "marker": {"color": color},
            "customdata": [[r[f"n_{outcome}"], r["n"]] for r in rows],
            "hovertemplate": f"%{{text}}<br>{name}: %{{y:.1%}} (%{{customdata[0]}} of %{{customdata[1]}})"
                             "<extra></extra>",
        })
    figure_layout = layout(
        title=title(parameter.name + (" (binned)" if parameter.binned else "")), barmode="stack", height=320,
        legend={"orientation": "h", "y": -0.3, "x": 0, "traceorder": "normal"},
        xaxis={"tickmode": "array", "tickvals": x, "ticktext": labels, "automargin": True,
               "range": [-0.5, len(rows) - 0.5]},
        yaxis=SHARE_AXIS,
    )
    sql = f"FROM outcomes_by_value WHERE parameter = '{parameter.name.replace(chr(39), chr(39) * 2)}'"
    return make_figure(f"fig-outcome-{index}", traces, figure_layout, sql)


def _iou_figure(rows: list[dict[str, Any]]) -> Figure | None:
    """Per object, the IoU's quartiles as a box, whiskers at the 10th and 90th percentiles, and its mean."""
    if not rows:
        return None
    trace = {
        "type": "box", "x": [plot_text(r["object"] + (f" ({r['misses']} of {r['n']} missed)" if r["misses"] else ""))
                            for r in rows], "q1": [r["p25"] for r in rows],
        "median": [r["median"] for r in rows], "q3": [r["p75"] for r in rows],
        "lowerfence": [r["p10"] for r in rows], "upperfence": [r["p90"] for r in rows],
        "mean": [r["mean"] for r in rows], "boxmean": True, "name": "IoU", "showlegend": False,
        "marker": {"color": COLORS["bar"]}, "line": {"color": COLORS["bar"]}, "fillcolor": COLORS["band"],
    }
    figure_layout = layout(
        title=title("IoU with the truth per object, a miss as 0 (box: quartiles; whiskers: 10th–90th percentile; "
                    "dashed: mean)"),
        height=340, xaxis={"type": "category", "automargin": True, "title": {"text": "object"}},
        yaxis={"range": [0, 1.02], "title": {"text": "IoU"}, "zeroline": False},
    )
    return make_figure("fig-iou", [trace], figure_layout, "FROM iou_by_object")
