"""Model comparison: is the second model more robust, and where is it worse?

Shown when the spec tests several models. Each model after the first is compared with the first
on the jobs both answered (see :mod:`sweep3d.results.compare`): overall accuracy with
McNemar's exact test and the models' agreement, accuracy per control value side by side with
95 % intervals, the regions where the difference holds after Holm's correction, and the images
the new model gets right that the first got wrong ("fixed") and the reverse ("broken").
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
    signed_points,
)
from sweep3d.report.panel import PanelInputs
from sweep3d.results import has_view

REGIONS = 12  # regions listed per pair
EXAMPLES = 8  # fixed and broken images shown per pair
MODEL_COLORS = (COLORS["bar"], COLORS["interaction"])


def build(inputs: PanelInputs) -> dict[str, Any] | None:
    """One block per model compared with the first; None when the spec tests one model."""
    if not has_view(inputs.con, "model_agreement"):
        return None
    pairs = inputs.rows("SELECT * FROM model_agreement WHERE model_a = (SELECT model FROM model_ranks "
                        "WHERE model_rank = 0) ORDER BY model_b")
    if not pairs:
        return None
    models = inputs.rows("SELECT * FROM model_accuracy")
    return {"models": [{"name": m["model"], "accuracy": pct(m["accuracy"]), "n": m["n"],
                        "interval": interval(m["wilson_low"], m["wilson_high"])} for m in models],
            "pairs": [_pair(inputs, pair, i) for i, pair in enumerate(pairs)]}


def _pair(inputs: PanelInputs, pair: dict[str, Any], index: int) -> dict[str, Any]:
    a, b = pair["model_a"], pair["model_b"]
    where = "WHERE model_a = ? AND model_b = ?"
    regions = inputs.rows(f"SELECT * FROM model_regions {where} LIMIT {REGIONS}", [a, b])
    levels = inputs.rows(f"SELECT * FROM model_comparison {where} ORDER BY position, level", [a, b])
    spread = "ORDER BY row_number() OVER (PARTITION BY object, environment ORDER BY job), object, environment, job"
    changes = {change: inputs.rows(f"SELECT * FROM model_changes {where} AND change = ? {spread} LIMIT {EXAMPLES}",
                                   [a, b, change]) for change in ("fixed", "broken")}  # a few of every scene
    return {
        "a": a, "b": b, "n": pair["n"], "fixed": pair["fixed"], "broken": pair["broken"],
        "accuracy_a": pct(pair["accuracy_a"]), "accuracy_b": pct(pair["accuracy_b"]),
        "difference": signed_points(pair["difference"]), "p_value": p_text(pair["p_value"]),
        "same_top1": pct(pair["same_top1"]), "kappa": "–" if pair["kappa"] is None else f"{pair['kappa']:.2f}",
        "regions": [{
            "terms": [(r[f"parameter_{s}"], r[f"label_{s}"]) for s in "ab" if r[f"parameter_{s}"] is not None],
            "accuracy_a": pct(r["accuracy_a"], 0), "accuracy_b": pct(r["accuracy_b"], 0),
            "difference": signed_points(r["difference"]), "n": r["n"], "fixed": r["fixed"], "broken": r["broken"],
            "p_value": p_text(r["p_value"]), "p_holm": p_text(r["p_holm"]), "verdict": r["verdict"],
        } for r in regions],
        "changes": {change: [_tile(inputs, row, a, b) for row in rows] for change, rows in changes.items()},
        "figure": _figure(levels, a, b, index) if levels else None,
    }


def _tile(inputs: PanelInputs, row: dict[str, Any], a: str, b: str) -> dict[str, Any]:
    """The second model's image of a changed job, captioned with both answers."""
    outcome = "correct" if row["change"] == "fixed" else "wrong"
    caption = f"{row['top1_a']} → {row['top1_b']}"
    return {"thumb": inputs.thumbs.want(row["image_key_b"]), "outcome": outcome, "caption": caption,
            "title": f"job {row['job']}: {row['object']} in {row['environment']}; {a}: {row['top1_a']}, "
                     f"{b}: {row['top1_b']} ({row['change']})"}


def _figure(levels: list[dict[str, Any]], a: str, b: str, index: int) -> Figure:
    """Accuracy of both models per control value, with 95 % Wilson intervals, on the same jobs."""
    labels = [plot_text(f"{r['parameter']} = {r['label']}") for r in levels]
    traces = []
    for side, model, color in (("a", a, MODEL_COLORS[0]), ("b", b, MODEL_COLORS[1])):
        acc = [r[f"accuracy_{side}"] for r in levels]
        traces.append({
            "type": "scatter", "mode": "markers", "name": plot_text(model), "y": labels, "x": acc,
            "marker": {"color": color, "size": 9, "symbol": "circle" if side == "a" else "diamond"},
            "error_x": {"type": "data", "symmetric": False, "color": color, "thickness": 1.2, "width": 3,
                        "array": [(r[f"wilson_high_{side}"] or 0) - (x or 0) for r, x in zip(levels, acc)],
                        "arrayminus": [(x or 0) - (r[f"wilson_low_{side}"] or 0) for r, x in zip(levels, acc)]},
            "customdata": [[r["n"], r["fixed"], r["broken"], r["p_value"]] for r in levels],
            "hovertemplate": f"{plot_text(model)}: %{{x:.1%}}<br>%{{y}}<br>%{{customdata[0]}} jobs; fixed "
                             "%{customdata[1]}, broken %{customdata[2]}; McNemar p %{customdata[3]:.3g}<extra></extra>",
        })
    figure_layout = layout(
        height=110 + 26 * len(levels), margin={"l": 16, "r": 16, "t": 28, "b": 40},
        legend={"orientation": "h", "y": 1.02, "yanchor": "bottom"},
        xaxis={**ACCURACY_AXIS, "title": {"text": "accuracy on the same jobs (95% Wilson interval)"}},
        yaxis={"type": "category", "autorange": "reversed", "automargin": True},
    )
    quoted = [name.replace("'", "''") for name in (a, b)]
    sql = ("SELECT parameter, label, accuracy_a, accuracy_b, fixed, broken, p_value FROM model_comparison "
           f"WHERE model_a = '{quoted[0]}' AND model_b = '{quoted[1]}'")
    return make_figure(f"fig-compare-{index}", traces, figure_layout, sql)
