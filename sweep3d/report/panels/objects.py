"""Per object: accuracy, the controls it is most sensitive to, and what it is taken for.

Sensitivity to a parameter is the share of the variance of ``correct`` (within the object's
results) that the parameter's levels explain beyond chance: epsilon squared, the same SQL as the
aggregate panel's "beyond chance" (``eta2_adjusted`` of the ``object_sensitivity`` macro). Only
levels with at least ``min_count`` of the object's results count (the rest are left out, as a
0 % of two images is no evidence), and the worst and best level are shown with their counts.
Wrong predictions come from ``object_confusions`` (for a box or mask task, its wrong-class
failures only; its wrong boxes and misses are counted beside them).
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from sweep3d.report.figures import Figure, interval, layout, make_figure, pct, plot_text
from sweep3d.report.panel import PanelInputs
from sweep3d.results import has_view, results_roles

SENSITIVE = 3  # parameters listed per object
CONFUSIONS = 3  # wrong predictions listed per object


def build(inputs: PanelInputs) -> dict[str, Any]:
    """One row per object, and a heat map of eta² per (object, parameter)."""
    con = inputs.con
    known = [p.name for p in inputs.parameters if p.name != "object"]
    sensitivity: dict[str, list[dict[str, Any]]] = defaultdict(list)
    sql = f"FROM object_sensitivity(min_count := {inputs.min_count})"
    for row in inputs.rows("SELECT object, parameter, eta2_adjusted, accuracy_min, worst_level, worst_n, "
                           f"accuracy_max, best_level, best_n {sql} WHERE list_contains(?, parameter)", [known]):
        sensitivity[row["object"]].append(row)
    confusions: dict[str, list[dict[str, Any]]] = defaultdict(list)
    if has_view(con, "object_confusions"):
        for row in inputs.rows("SELECT object, prediction, n, share FROM object_confusions WHERE rank <= ?",
                               [CONFUSIONS]):
            confusions[row["object"]].append(row)
    box_failures = _box_failures(inputs)
    labels = {o.name: ", ".join(str(label) for label in o.labels) for o in inputs.loaded.spec.objects}
    objects = []
    for row in inputs.rows("SELECT label AS object, level, n, accuracy, wilson_low, wilson_high FROM control_accuracy "
                           "WHERE parameter = 'object' ORDER BY accuracy NULLS LAST, label"):
        objects.append({
            "object": row["object"], "labels": labels.get(row["object"], ""), "count": row["n"],
            "accuracy": pct(row["accuracy"]), "interval": interval(row["wilson_low"], row["wilson_high"]),
            "sensitive": [_sensitivity(s) for s in sensitivity[row["object"]] if s["eta2_adjusted"]][:SENSITIVE],
            "confusions": [_confusion(inputs, row["level"], c) for c in confusions[row["object"]]],
            "box_failures": (box_failures or {}).get(row["object"], []),
        })
    return {"objects": objects, "min_count": inputs.min_count, "box_task": box_failures is not None,
            "figure": _figure(sensitivity, [o["object"] for o in objects], known, sql, inputs.min_count)}


def _box_failures(inputs: PanelInputs) -> dict[str, list[str]] | None:
    """Per object, its failures with the right class (``3 wrong box``, ``2 missed``): a box or mask
    task's failures that "taken for" must not list as confusions. None for other tasks."""
    roles = results_roles(inputs.con)
    if not roles.has("outcome"):
        return None
    out: dict[str, list[str]] = defaultdict(list)
    for row in inputs.rows(f'SELECT object, "{roles.outcome}" AS outcome, count(*) AS n FROM results '
                           f"WHERE counted AND NOT correct AND \"{roles.outcome}\" IN ('wrong_box', 'missed') "
                           "GROUP BY ALL ORDER BY object, outcome DESC"):
        out[row["object"]].append(f"{row['n']} {row['outcome'].replace('_', ' ')}")
    return out


def _sensitivity(row: dict[str, Any]) -> dict[str, Any]:
    share = row["eta2_adjusted"]
    return {"parameter": row["parameter"], "share": "< 1%" if 0 < share < 0.005 else pct(share, 0),
            "worst": row["worst_level"], "worst_accuracy": pct(row["accuracy_min"], 0), "worst_n": row["worst_n"],
            "best": row["best_level"], "best_accuracy": pct(row["accuracy_max"], 0), "best_n": row["best_n"]}


def _confusion(inputs: PanelInputs, level: int, row: dict[str, Any]) -> dict[str, Any]:
    """A wrong prediction with its count, share and its highest-loss example."""
    example = inputs.results.examples({"object": level}, 1, prediction=row["prediction"])
    return {"prediction": row["prediction"], "count": row["n"], "share": pct(row["share"], 0),
            "example": inputs.tile(example[0]) if example else None}


def _figure(sensitivity: dict[str, list[dict[str, Any]]], objects: list[str], parameters: list[str], sql: str,
            min_count: int) -> Figure | None:
    """Heat map: share of each object's variance explained by each parameter beyond chance."""
    cells = {(r["object"], r["parameter"]): r for rows in sensitivity.values() for r in rows}
    columns = [p for p in parameters if any((o, p) in cells for o in objects)]
    if not columns or not objects:
        return None
    z = [[cells[(o, p)]["eta2_adjusted"] if (o, p) in cells else None for p in columns] for o in objects]
    if all(v is None for row in z for v in row):  # no object has both right and wrong results
        return None
    hover = [[_hover(cells.get((o, p)), min_count) for p in columns] for o in objects]
    trace = {
        "type": "heatmap", "z": z, "x": [plot_text(p) for p in columns], "y": [plot_text(o) for o in objects],
        "zmin": 0, "zmax": max([v for row in z for v in row if v is not None] + [0.05]), "colorscale": "Reds",
        "text": [[f"{v:.0%}" if v is not None else "" for v in row] for row in z], "texttemplate": "%{text}",
        "hovertext": hover, "hovertemplate": "%{y} · %{x}<br>%{hovertext}<extra></extra>", "xgap": 2, "ygap": 2,
        "colorbar": {"tickformat": ".0%", "title": {"text": "ε²"}},
    }
    figure_layout = layout(
        height=max(220, 110 + 34 * len(objects)), margin={"l": 16, "r": 16, "t": 16, "b": 48},
        xaxis={"type": "category", "automargin": True, "title": {"text": "parameter"}},
        yaxis={"type": "category", "automargin": True, "autorange": "reversed"},
    )
    return make_figure("fig-object-sensitivity", [trace], figure_layout, sql)


def _hover(cell: dict[str, Any] | None, min_count: int) -> str:
    if cell is None:
        return f"fewer than two values with {min_count} or more results"
    return (f"explains {pct(cell['eta2_adjusted'], 0)} of the variance beyond chance<br>"
            f"worst {plot_text(cell['worst_level'])}: {pct(cell['accuracy_min'], 0)} of {cell['worst_n']}<br>"
            f"best {plot_text(cell['best_level'])}: {pct(cell['accuracy_max'], 0)} of {cell['best_n']}")
