"""Failure boundaries: where along each numeric control the model starts to fail.

One small figure per significant boundary of a control with more than two values (overall first,
then single objects and environments, most certain first; a two-valued control's boundary is only
its two values, which the table gives): the accuracy of the group's results in equal-width bins of the value (points
with their 95 % Wilson interval, counts in the hover), the fitted step, and the boundary with
its 95 % interval as a band. A table lists every fit, boundaries first; a fit without a
significant step says so ("no boundary"). Numbers from ``failure_boundaries`` (see
:mod:`sweep3d.results.boundaries`), which the report registers on its connection.
"""

from __future__ import annotations

from typing import Any

from sweep3d.report.figures import ACCURACY_AXIS, COLORS, Figure, layout, make_figure, p_text, pct, title
from sweep3d.report.panel import PanelInputs
from sweep3d.results import VIEW, Scale, boundary_phrase, control_number, has_view, identifier, literal, numeric_scales

FIGURES = 8  # boundaries drawn
BINS = 10  # equal-width bins of a group's values in its figure


def build(inputs: PanelInputs) -> dict[str, Any] | None:
    """Every fit's row, figures of the significant ones; None when nothing was fitted (no numeric
    parameter, or none with enough results)."""
    if not has_view(inputs.con, VIEW):
        return None
    fits = inputs.rows(f"FROM {VIEW} ORDER BY NOT significant, scope <> 'all', q_value, position, "
                       "object NULLS FIRST, environment NULLS FIRST")
    if not fits:
        return None
    scales = numeric_scales(inputs.loaded.controls)
    # a two-valued control's "boundary" is only its two values: the table says it, no chart draws it
    shown = [fit for fit in fits if fit["significant"] and fit["values"] > 2][:FIGURES]
    figures = [_figure(inputs, i, fit, scales.get(fit["parameter"], Scale())) for i, fit in enumerate(shown, 1)]
    return {"figures": figures, "rows": [_row(fit) for fit in fits], "two_valued": sum(
                fit["significant"] and fit["values"] == 2 for fit in fits),
            "boundaries": sum(fit["significant"] for fit in fits), "fits": len(fits)}


def _who(fit: dict[str, Any]) -> str:
    """``all results``, ``object toaster`` or ``environment forest``."""
    return "all results" if fit["scope"] == "all" else f"{fit['scope']} {fit[fit['scope']]}"


def _value(value: float | None) -> str:
    return "–" if value is None else control_number(value)


def _row(fit: dict[str, Any]) -> dict[str, Any]:
    """A table row: the group, the boundary (or none) with its interval, the two plateaus and the test."""
    return {"parameter": fit["parameter"], "who": _who(fit), "significant": fit["significant"],
            "verdict": boundary_phrase(fit) if fit["significant"] else None,
            "interval": f"{_value(fit['boundary_low'])}–{_value(fit['boundary_high'])}",
            "below": f"{pct(fit['accuracy_below'], 0)} of {fit['n_below']}",
            "above": f"{pct(fit['accuracy_above'], 0)} of {fit['n_above']}",
            "n": fit["n"], "distinct": fit["values"], "p_value": p_text(fit["p_value"]), "q_value": p_text(fit["q_value"])}


def _bins(inputs: PanelInputs, fit: dict[str, Any], log: bool) -> list[dict[str, Any]]:
    """The group's counted results in :data:`BINS` equal-width bins of the value (of its log for a
    log range): mean value, results, correct, accuracy and its Wilson interval per bin."""
    x = f"CAST({identifier(fit['parameter'])} AS DOUBLE)"
    t = f"ln({x})" if log else x
    where = [f"counted AND isfinite({x})" + (f" AND {x} > 0" if log else "")]
    for scope in ("object", "environment"):
        if fit["scope"] == scope:
            where.append(f"{scope} = {literal(fit[scope])}")
    return inputs.rows(f"""
        WITH g AS (SELECT {x} AS x, {t} AS t, correct FROM results WHERE {' AND '.join(where)}),
        s AS (SELECT min(t) AS lo, max(t) AS hi FROM g)
        SELECT bin, avg(x) AS x, count(*) AS n, count(*) FILTER (WHERE correct) AS n_correct,
               count(*) FILTER (WHERE correct) / count(*) AS accuracy,
               wilson_low(count(*) FILTER (WHERE correct), count(*)) AS low,
               wilson_high(count(*) FILTER (WHERE correct), count(*)) AS high
        FROM (SELECT g.*, least(floor((t - lo) / nullif(hi - lo, 0) * {BINS}), {BINS - 1}) AS bin FROM g, s)
        GROUP BY bin ORDER BY bin""")


def _figure(inputs: PanelInputs, index: int, fit: dict[str, Any], scale: Scale) -> Figure:
    """Binned accuracy against the value, the fitted step, the boundary and its 95 % interval (band)."""
    bins = _bins(inputs, fit, scale.log)
    lo, hi = min(b["x"] for b in bins), max(b["x"] for b in bins)
    boundary = fit["boundary"]
    points = {
        "type": "scatter", "mode": "markers", "x": [b["x"] for b in bins], "y": [b["accuracy"] for b in bins],
        "customdata": [[b["n_correct"], b["n"]] for b in bins], "name": "binned accuracy",
        "marker": {"color": COLORS["bar"], "size": [6 + min(10, b["n"] ** 0.5) for b in bins]},
        "error_y": {"type": "data", "symmetric": False, "color": COLORS["muted"], "thickness": 1.2,
                    "array": [b["high"] - b["accuracy"] for b in bins],
                    "arrayminus": [b["accuracy"] - b["low"] for b in bins]},
        "hovertemplate": "around %{x:.3g}: %{y:.0%} (%{customdata[0]} of %{customdata[1]})<extra></extra>",
    }
    step = {
        "type": "scatter", "mode": "lines", "x": [lo, boundary, boundary, hi],
        "y": [fit["accuracy_below"], fit["accuracy_below"], fit["accuracy_above"], fit["accuracy_above"]],
        "line": {"color": COLORS["wrong"], "width": 2}, "name": "step fit", "hoverinfo": "skip",
    }
    shapes = [
        {"type": "rect", "xref": "x", "yref": "paper", "x0": fit["boundary_low"], "x1": fit["boundary_high"],
         "y0": 0, "y1": 1, "fillcolor": "rgba(214, 69, 69, 0.15)", "line": {"width": 0}, "layer": "below"},
        {"type": "line", "xref": "x", "yref": "paper", "x0": boundary, "x1": boundary, "y0": 0, "y1": 1,
         "line": {"color": COLORS["wrong"], "dash": "dash", "width": 1.5}},
    ][: 1 if fit["values"] == 2 else 2]  # two values: the band is the whole gap, and no place in it is the boundary
    heading = f"{_who(fit)}: {boundary_phrase(fit)}" + (
        "" if fit["values"] == 2 else f" ({_value(fit['boundary_low'])}–{_value(fit['boundary_high'])})")
    figure_layout = layout(
        title=title(heading), height=240, shapes=shapes, showlegend=False,
        margin={"l": 48, "r": 8, "t": 36, "b": 40},
        xaxis={"title": {"text": fit["parameter"]}, "type": "log" if scale.log else "linear", "zeroline": False},
        yaxis=ACCURACY_AXIS,
    )
    where = " AND ".join([f"parameter = {literal(fit['parameter'])}", f"scope = {literal(fit['scope'])}"]
                         + [f"{s} = {literal(fit[s])}" for s in ("object", "environment") if fit["scope"] == s])
    return make_figure(f"fig-boundary-{index}", [step, points], figure_layout, f"FROM {VIEW} WHERE {where}")
