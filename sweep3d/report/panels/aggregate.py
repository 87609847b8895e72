"""Aggregate: accuracy against each parameter with 95 % Wilson bands, box plots over scenes
(3DB's Figure 4), and the share of variance each parameter and pair of parameters explains."""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from sweep3d.report.figures import ACCURACY_AXIS, COLORS, Figure, layout, make_figure, plot_text, title
from sweep3d.report.panel import PanelInputs
from sweep3d.report.reading import Parameter

EFFECTS = 16  # bars in the variance chart


def build(inputs: PanelInputs) -> dict[str, Any]:
    """Per-parameter accuracy figures, the two box plots and the variance chart."""
    parameters = [p for p in inputs.parameters if p.varies and p.name != "object"]
    levels = defaultdict(list)
    for row in inputs.rows("SELECT parameter, label, n, accuracy, wilson_low, wilson_high FROM control_accuracy "
                           "ORDER BY position, level"):
        levels[row["parameter"]].append(row)
    effects = [_effect_figure(i, p, levels[p.name]) for i, p in enumerate(parameters, 1)]
    scenes = inputs.rows("SELECT object, environment, n, accuracy FROM scene_accuracy WHERE n > 0")
    boxes = [_box_figure(scenes, "environment", "object"), _box_figure(scenes, "object", "environment")]
    return {"effects": effects, "boxes": boxes, "variance": _variance_figure(inputs)}


def _effect_figure(index: int, parameter: Parameter, rows: list[dict[str, Any]]) -> Figure:
    """Accuracy at each level: a line with a shaded band (numeric), or bars with error bars."""
    x = list(range(len(rows)))
    accuracy = [r["accuracy"] for r in rows]
    custom = [[r["n"], r["wilson_low"], r["wilson_high"]] for r in rows]
    hover = ("%{text}<br>accuracy %{y:.1%}<br>95% CI %{customdata[1]:.0%}–%{customdata[2]:.0%}"
             "<br>%{customdata[0]} results<extra></extra>")
    labels = [plot_text(r["label"]) for r in rows]
    if parameter.numeric:
        band_x = x + x[::-1]
        band_y = [r["wilson_high"] for r in rows] + [r["wilson_low"] for r in rows][::-1]
        data = [
            {"type": "scatter", "mode": "lines", "x": band_x, "y": band_y, "fill": "toself",
             "fillcolor": COLORS["band"], "line": {"width": 0}, "hoverinfo": "skip", "name": "95% Wilson interval",
             "showlegend": False},
            {"type": "scatter", "mode": "lines+markers", "x": x, "y": accuracy, "text": labels, "customdata": custom,
             "line": {"color": COLORS["bar"], "width": 2}, "marker": {"size": 6}, "hovertemplate": hover,
             "name": "accuracy", "showlegend": False, "connectgaps": False},
        ]
    else:
        data = [{"type": "bar", "x": x, "y": accuracy, "text": labels, "textposition": "none", "customdata": custom,
                 "marker": {"color": COLORS["bar"]}, "hovertemplate": hover, "showlegend": False,
                 "error_y": {"type": "data", "symmetric": False, "color": COLORS["muted"], "thickness": 1.2,
                             "array": [_gap(r["wilson_high"], r["accuracy"]) for r in rows],
                             "arrayminus": [_gap(r["accuracy"], r["wilson_low"]) for r in rows]}}]
    figure_layout = layout(
        title=title(parameter.name + (" (binned)" if parameter.binned else "")), height=300,
        xaxis={"tickmode": "array", "tickvals": x, "ticktext": labels, "automargin": True,
               "range": [-0.5, len(rows) - 0.5]},
        yaxis=ACCURACY_AXIS,
    )
    sql = f"FROM control_accuracy WHERE parameter = '{parameter.name.replace(chr(39), chr(39) * 2)}'"
    return make_figure(f"fig-effect-{index}", data, figure_layout, sql)


def _box_figure(scenes: list[dict[str, Any]], group: str, over: str) -> Figure:
    """For each ``group`` value, the spread over ``over`` of per-(object, environment) accuracy."""
    groups: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for row in scenes:
        groups[row[group]].append(row)
    order = sorted(groups, key=lambda g: (sum(r["accuracy"] for r in groups[g]) / len(groups[g]), g))
    data = [{
        "type": "box", "name": plot_text(g), "y": [r["accuracy"] for r in groups[g]],
        "text": [plot_text(r[over]) for r in groups[g]], "customdata": [r["n"] for r in groups[g]],
        "boxpoints": "all", "jitter": 0.35, "pointpos": 0, "marker": {"color": COLORS["bar"], "size": 5},
        "line": {"color": COLORS["bar"]}, "fillcolor": COLORS["band"], "showlegend": False,
        "hovertemplate": f"{group} %{{x}}<br>{over} %{{text}}: %{{y:.0%}} of %{{customdata}}<extra></extra>",
    } for g in order]
    figure_layout = layout(
        title=title(f"accuracy by {group}, spread over {over}s"), height=340,
        xaxis={"type": "category", "automargin": True, "title": {"text": group}}, yaxis=ACCURACY_AXIS,
    )
    return make_figure(f"fig-box-{group}", data, figure_layout, "FROM scene_accuracy")


def _variance_figure(inputs: PanelInputs) -> Figure | None:
    """Horizontal bars: eta² of each main effect and interaction, and its part beyond chance."""
    known = [p.name for p in inputs.parameters]
    rows = inputs.rows(
        "SELECT kind, effect, eta2, eta2_adjusted, df FROM variance_explained WHERE eta2 IS NOT NULL "
        "AND list_contains(?, parameter_a) AND (parameter_b IS NULL OR list_contains(?, parameter_b)) LIMIT ?",
        [known, known, EFFECTS])
    if not rows:
        return None
    names = [plot_text(r["effect"]) for r in rows]
    colors = [COLORS["bar"] if r["kind"] == "main" else COLORS["interaction"] for r in rows]
    custom = [[r["kind"], r["df"], r["eta2"]] for r in rows]
    data = [
        {"type": "bar", "orientation": "h", "y": names, "x": [r["eta2"] for r in rows], "name": "eta²",
         "marker": {"color": colors, "opacity": 0.35}, "customdata": custom,
         "hovertemplate": "%{y} (%{customdata[0]}, %{customdata[1]} df)<br>eta² %{x:.1%}<extra></extra>"},
        {"type": "bar", "orientation": "h", "y": names, "x": [r["eta2_adjusted"] for r in rows],
         "name": "beyond chance (ε²)", "marker": {"color": colors}, "customdata": custom,
         "hovertemplate": "%{y}<br>beyond chance %{x:.1%} (eta² %{customdata[2]:.1%})<extra></extra>"},
    ]
    figure_layout = layout(
        title=title("share of the variance of correct explained"), barmode="overlay", showlegend=False,
        height=100 + 24 * len(rows), margin={"l": 16, "r": 16, "t": 40, "b": 40},
        xaxis={"tickformat": ".0%", "rangemode": "tozero", "title": {"text": "share of variance"}},
        yaxis={"type": "category", "autorange": "reversed", "automargin": True},
    )
    return make_figure("fig-variance", data, figure_layout, "FROM variance_explained")


def _gap(high: float | None, low: float | None) -> float | None:
    return None if high is None or low is None else high - low
