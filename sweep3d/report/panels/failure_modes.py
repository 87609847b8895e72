"""Failure modes: the control regions where the model does significantly worse than elsewhere.

A region is one level of a parameter, or a pair of levels of two parameters (listed only when
the pair is confidently worse than each level alone). Each is compared with the rest of its
parameter (McNemar's exact test where the design pairs a two-level parameter, else Fisher's),
and called significant at a false discovery rate of 5 % over every region tested
(Benjamini–Hochberg ``q_value`` < 0.05). Regions are ranked by the upper end of the 95 %
interval of their difference from the rest: the most certainly large drop first. The table and
the figure show the significant regions; the others are listed apart, greyed, without examples.
The list comes from the ``failure_modes`` SQL macro (see
:mod:`sweep3d.results.failure_modes`).
"""

from __future__ import annotations

from typing import Any

from sweep3d.report.figures import COLORS, Figure, interval, layout, make_figure, p_text, pct, plot_text
from sweep3d.report.panel import PanelInputs

TOP = 12  # regions listed
TESTS = {"mcnemar": "McNemar (paired)", "fisher": "Fisher"}
EXAMPLES = 4  # wrong predictions shown per region


def build(inputs: PanelInputs) -> dict[str, Any]:
    """The ranked significant regions, each with examples, a dot plot of their difference from the
    rest of their parameter, and the regions below the rest that are not significantly below it."""
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
        "figure": _figure(modes, sql) if modes else None,
        "gap": _gap(inputs, weak) if not modes else None,
    }


def _gap(inputs: PanelInputs, weak: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The value nearest to significance, as ``run``'s findings name it (the summary's gap)."""
    gap = inputs.summary.gap
    if gap is None:
        return None
    found = [m for m in weak if m["size"] == 1 and (m["parameter_a"], m["label_a"]) == (gap["column"], gap["label"])]
    rows = found or inputs.rows(f"FROM failure_modes(min_count := {inputs.min_count}) WHERE size = 1 "
                                "AND parameter_a = ? AND label_a = ?", [gap["column"], gap["label"]])
    return _row(rows[0]) if rows else None


def _terms(mode: dict[str, Any]) -> list[tuple[str, int, str]]:
    """(parameter, level, label) of each of the region's one or two values."""
    return [(mode[f"parameter_{s}"], mode[f"level_{s}"], mode[f"label_{s}"]) for s in "ab"
            if mode[f"parameter_{s}"] is not None]


def _row(mode: dict[str, Any]) -> dict[str, Any]:
    """A table row: the region's values, accuracy and interval, the rest's accuracy, the difference
    with its interval, counts, the test and its q-value."""
    return {"terms": [(parameter, label) for parameter, _, label in _terms(mode)],
            "accuracy": pct(mode["accuracy"], 0), "interval": interval(mode["wilson_low"], mode["wilson_high"]),
            "rest": pct(mode["accuracy_rest"], 0), "count_rest": mode["n_rest"],
            "difference": points(mode["difference"]),
            "difference_interval": f"{points(mode['difference_low'])} to {points(mode['difference_high'])}",
            "wrong": mode["n"] - mode["n_correct"], "count": mode["n"], "test": TESTS[mode["test"]],
            "q_value": p_text(mode["q_value"]), "p_overall": p_text(mode["p_holm_overall"])}


def points(difference: float | None) -> str:
    """A difference of two accuracies in percentage points: ``−50``, ``+3``."""
    return "–" if difference is None else f"{100 * difference:+.0f}".replace("-", "−")


def _figure(modes: list[dict[str, Any]], sql: str) -> Figure:
    """Each region's difference from the rest of its parameter (dot) with its 95 % interval (bar),
    worst at the top; 0 (no difference) dotted."""
    labels = [f"{i + 1}. " + plot_text(m["region"]) for i, m in enumerate(modes)]
    trace = {
        "type": "scatter", "mode": "markers", "y": labels, "x": [100 * m["difference"] for m in modes],
        "marker": {"color": COLORS["wrong"], "size": 9},
        "error_x": {"type": "data", "symmetric": False, "color": COLORS["muted"], "thickness": 1.5, "width": 4,
                    "array": [100 * (m["difference_high"] - m["difference"]) for m in modes],
                    "arrayminus": [100 * (m["difference"] - m["difference_low"]) for m in modes]},
        "customdata": [[m["n"], m["n"] - m["n_correct"], m["accuracy"], m["accuracy_rest"], m["n_rest"],
                        100 * m["difference_low"], 100 * m["difference_high"]] for m in modes],
        "hovertemplate": "%{y}<br>%{x:+.0f} points: %{customdata[2]:.0%} of %{customdata[0]} against "
                         "%{customdata[3]:.0%} of the other %{customdata[4]}"
                         "<br>95% CI %{customdata[5]:+.0f} to %{customdata[6]:+.0f} points<extra></extra>",
        "showlegend": False,
    }
    shapes = [{"type": "line", "xref": "x", "yref": "paper", "x0": 0, "x1": 0, "y0": 0, "y1": 1,
               "line": {"color": COLORS["bar"], "dash": "dot", "width": 1.5}}]
    figure_layout = layout(
        height=90 + 30 * len(modes), margin={"l": 16, "r": 16, "t": 28, "b": 40}, shapes=shapes,
        xaxis={"range": [-100, 5], "title": {"text": "accuracy less the rest of the parameter's, points (95% CI)"},
               "zeroline": False},
        yaxis={"type": "category", "autorange": "reversed", "automargin": True},
    )
    return make_figure("fig-failure-modes", [trace], figure_layout, sql)
