"""Worst failures: the wrong predictions, worst first (the highest loss; for a box or mask task
without a loss, the lowest IoU, misses first), each with its top-k (and, for box and mask tasks,
how it failed and its IoU; the thumbnail shows the true and predicted boxes).

The page shows them as a compact grid of thumbnails captioned with the top-1 label; each one's
scene, controls, top-k and loss are in a table a click away (near-identical cards made this panel
the page's tallest)."""

from __future__ import annotations

from typing import Any

from sweep3d.core import Roles
from sweep3d.report.figures import pct
from sweep3d.report.panel import PanelInputs
from sweep3d.results import fragile_sentence, results_roles


def build(inputs: PanelInputs) -> dict[str, Any]:
    """The summary's failures: thumbnail, scene, the values of the controls that vary, top-k, loss."""
    failures = inputs.summary.failures
    varying = {p.name for p in inputs.parameters if p.varies}  # a fixed one is stated once, in the header
    columns = [c for c in inputs.loaded.parameter_columns if c in varying]
    present = {row[0] for row in inputs.con.execute("DESCRIBE results").fetchall()}  # its evaluator's only
    roles = results_roles(inputs.con)
    task = [c if has else f"NULL AS {c}" for c, has in
            (("outcome", roles.has("outcome")), ("iou", roles.has("iou")), ("topk", "topk" in present))]
    selected = "".join(f', "{c}"' for c in columns)
    extra = {row[0]: row[1:] for row in inputs.con.execute(
        f"SELECT job, {', '.join(task)}{selected} FROM results WHERE list_contains(?, job)",
        [[f["job"] for f in failures]]).fetchall()} if failures else {}
    cards = []
    for failure in failures:
        outcome, iou, topk_ids, *values = extra.get(failure["job"], (None, None, None))
        truth = set(inputs.loaded.labels.get(failure["object"], ()))
        names = failure["topk_labels"] or ([failure["top1_label"]] if failure["top1_label"] else [])
        ids = topk_ids or [None] * len(names)
        cards.append({
            "job": failure["job"],
            "object": failure["object"],
            "environment": failure["environment"],
            "thumb": inputs.thumbs.want(failure["image_key"]),
            "controls": [(c, _fmt(v)) for c, v in zip(columns, values) if v is not None],
            "topk": [{"label": name, "prob": pct(prob), "truth": i in truth or name in truth}
                     for name, prob, i in zip(names, failure["topk_probs"] or [None] * len(names), ids)],
            "loss": f"{failure['loss']:.2f}" if failure["loss"] is not None else "",
            "outcome": _outcome(outcome, iou),
        })
    return {"cards": cards, "wrong": inputs.summary.wrong, "order": _order(roles),
            "k": max((len(c["topk"]) for c in cards), default=1),
            "truth_note": _truth_note(cards, roles), "fragile": fragile_sentence(inputs.summary)}


def _order(roles: Roles) -> str:
    """What "worst" means here, as the summary sorts its failures."""
    if roles.has("loss"):
        return "with the highest loss"
    if roles.has("iou"):
        return "with the lowest IoU (misses first)"
    return "first, in job order"


def _truth_note(cards: list[dict[str, Any]], roles: Roles) -> str:
    """What the green label says: the truth among the top k, or, with one class shown, a right
    class (for a box or mask task, the failure was then the box)."""
    k = max((len(c["topk"]) for c in cards), default=0)
    if k > 1:
        return f"the true label is green where it is among the top {k}"
    if roles.has("outcome"):
        return "the predicted class is green where it is right: the box or mask failed, not the class"
    return "the predicted class is green where it is right"


def _outcome(outcome: str | None, iou: float | None) -> str:
    """``wrong box · IoU 0.31`` for a box or mask task's failure ("" for classification)."""
    parts = [outcome.replace("_", " ")] if outcome else []
    return " · ".join(parts + ([f"IoU {iou:.2f}"] if iou is not None else []))


def _fmt(value: Any) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)
