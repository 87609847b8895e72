"""Paired comparisons: environment A against B (and skin against skin, …) on the same poses.

Shown when the spec asks for a paired design (``[policy] paired``): its environments were then
tried on the same points, so each difference is paired and McNemar's exact test on the
discordant pairs says whether it is more than chance (see :mod:`sweep3d.results.paired`).
Lists the pairs of environments, then the pairs of values of the other listed parameters that
have pairs, and the images of the pair of environments whose difference is the most certain.
"""

from __future__ import annotations

from typing import Any

from sweep3d.report.figures import p_text, pct, signed_points
from sweep3d.report.panel import PanelInputs
from sweep3d.results import has_view
from sweep3d.spec import Choice, parameter_column

ROWS = 24  # value pairs listed per table
EXAMPLES = 6  # discordant image pairs shown


def build(inputs: PanelInputs) -> dict[str, Any] | None:
    """The tables and examples; None when the spec is not paired or nothing pairs."""
    if not inputs.loaded.spec.policy.paired or not has_view(inputs.con, "paired_environments"):
        return None
    environments = inputs.rows(f"SELECT * FROM paired_environments LIMIT {ROWS}")
    columns = [parameter_column(c.id, p) for c in inputs.loaded.controls for p, s in c.spaces.items()
               if isinstance(s, Choice)]  # a range's draws do not repeat, so they never pair
    # one query per parameter: a constant filter computes only that parameter's pairs
    others = [r for column in columns for r in inputs.rows(f"SELECT * FROM paired_values WHERE parameter = ? "
                                                           f"LIMIT {ROWS}", [column])][:ROWS]
    if not environments and not others:
        return None
    return {"environments": [_row(r, r["environment_a"], r["environment_b"]) for r in environments],
            "others": [{**_row(r, r["value_a"], r["value_b"]), "parameter": r["parameter"]} for r in others],
            "examples": _examples(inputs, environments)}


def _row(r: dict[str, Any], a: str, b: str) -> dict[str, Any]:
    return {"a": a, "b": b, "n": r["n"], "accuracy_a": pct(r["accuracy_a"]), "accuracy_b": pct(r["accuracy_b"]),
            "a_only": r["a_right_b_wrong"], "b_only": r["a_wrong_b_right"], "difference": signed_points(r["difference"]),
            "p_value": p_text(r["p_value"]), "p_holm": p_text(r["p_holm"]),
            "verdict": "same" if r["p_holm"] is None or r["p_holm"] >= 0.05 else
                       ("better" if r["difference"] > 0 else "worse")}


def _examples(inputs: PanelInputs, environments: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The discordant pairs of the pair of environments with the smallest p-value, both images each."""
    discordant = [r for r in environments if r["a_right_b_wrong"] + r["a_wrong_b_right"]]
    if not discordant:
        return None
    top = min(discordant, key=lambda r: r["p_value"])
    a, b = top["environment_a"], top["environment_b"]
    pairs = inputs.rows("SELECT * FROM paired_jobs WHERE parameter = 'environment' AND value_a = ? AND value_b = ? "
                        f"AND correct_a <> correct_b ORDER BY correct_b, job_a LIMIT {EXAMPLES}", [a, b])
    return {"a": a, "b": b, "pairs": [[_tile(inputs, p, side) for side in "ab"] for p in pairs]}


def _tile(inputs: PanelInputs, pair: dict[str, Any], side: str) -> dict[str, Any]:
    right = pair[f"correct_{side}"]
    where = pair[f"environment_{side}"]
    return {"thumb": inputs.thumbs.want(pair[f"image_key_{side}"]), "outcome": "correct" if right else "wrong",
            "caption": f"{where}: {'right' if right else 'wrong'}",
            "title": f"job {pair[f'job_{side}']}: {pair[f'object_{side}']} in {where}"}
