"""Shared look of the report's plotly figures, and text helpers for them.

Every figure travels as plotly JSON; the page draws it with PNG export in the mode bar.
Text shown by plotly (tick labels, hover) goes through :func:`plot_text`: plotly reads a small
HTML subset in labels, so names are escaped to show literally.
"""

from __future__ import annotations

import html
import itertools
import json
from dataclasses import dataclass
from typing import Any

COLORS = {"correct": "#2e9d5b", "wrong": "#d64545", "invalid": "#9aa0a6", "bar": "#4c72b0",
          "band": "rgba(76, 114, 176, 0.18)", "muted": "#656d76", "interaction": "#dd8452"}
FONT = "system-ui, -apple-system, Segoe UI, Roboto, sans-serif"
#: Red (0 %) to green (100 %), as a plotly colorscale (plotly.js knows no name for it).
ACCURACY_COLORSCALE = [[i / 10, c] for i, c in enumerate([
    "rgb(165,0,38)", "rgb(215,48,39)", "rgb(244,109,67)", "rgb(253,174,97)", "rgb(254,224,139)", "rgb(255,255,191)",
    "rgb(217,239,139)", "rgb(166,217,106)", "rgb(102,189,99)", "rgb(26,152,80)", "rgb(0,104,55)"])]


def accuracy_rgb(accuracy: float) -> tuple[float, float, float]:
    """The colour of ``accuracy`` (0..1) on :data:`ACCURACY_COLORSCALE`, as sRGB floats in [0, 1]."""
    stops = [(at, [int(c) / 255 for c in colour[4:-1].split(",")]) for at, colour in ACCURACY_COLORSCALE]
    x = min(max(float(accuracy), 0.0), 1.0)
    for (lo, a), (hi, b) in itertools.pairwise(stops):
        if x <= hi:
            t = (x - lo) / (hi - lo)
            return tuple(ca + t * (cb - ca) for ca, cb in zip(a, b))
    return tuple(stops[-1][1])


ACCURACY_AXIS = {"range": [0, 1.05], "tickformat": ".0%", "title": {"text": "accuracy"}, "zeroline": False}


def layout(**extra: Any) -> dict[str, Any]:
    """A plotly layout in the report's style, updated with ``extra``."""
    base = {
        "template": "plotly_white",
        "font": {"family": FONT, "size": 12},
        "margin": {"l": 56, "r": 16, "t": 40, "b": 48},
        "hoverlabel": {"font": {"family": FONT}},
    }
    return {**base, **extra}


def layout_json(**extra: Any) -> dict[str, Any]:
    """:func:`layout` as plotly.js takes it (the template expanded), for figures drawn in JS."""
    import plotly.graph_objects as go

    return json.loads(go.Figure(layout=layout(**extra)).to_json())["layout"]


def title(text: str) -> dict[str, Any]:
    """A small left-aligned figure title (``text`` escaped)."""
    return {"text": plot_text(text), "x": 0.02, "font": {"size": 14}}


def plot_text(value: Any) -> str:
    """Text for plotly, which reads a small HTML subset in labels: escape so names show literally."""
    return html.escape(str(value), quote=False)


def pct(value: float | None, digits: int = 1) -> str:
    """``0.1234`` → ``12.3%``; None → ``–``."""
    return "–" if value is None else f"{value:.{digits}%}"


def p_text(value: float | None) -> str:
    """A p-value as the report prints it: three decimals, or ``< 0.001``; None → ``–``."""
    if value is None:
        return "–"
    return "< 0.001" if value < 0.001 else f"{value:.3f}"


def interval(low: float | None, high: float | None) -> str:
    """A Wilson interval as ``[10–25 %]`` (empty when unknown)."""
    if low is None or high is None:
        return ""
    return f"[{low:.0%}–{high:.0%}]".replace("%–", "–")


def figure_json(data: list[dict[str, Any]], figure_layout: dict[str, Any]) -> str:
    """Validate ``data`` and ``layout`` with plotly and return the figure as JSON."""
    import plotly.graph_objects as go

    return go.Figure(data=data, layout=figure_layout).to_json()


@dataclass(frozen=True)
class Figure:
    """One plot of a panel.

    Attributes:
        id: the HTML id of the plot's element (also the name of its PNG export).
        json: the plotly figure.
        query: SQL (for ``sweep3d query``) printing the numbers behind it, if any.
    """

    id: str
    json: str
    query: str | None = None


def make_figure(figure_id: str, data: list[dict[str, Any]], figure_layout: dict[str, Any],
                query: str | None = None) -> Figure:
    """A :class:`Figure` from plotly ``data`` and ``layout`` (validated by plotly)."""
    return Figure(figure_id, figure_json(data, figure_layout), query)
