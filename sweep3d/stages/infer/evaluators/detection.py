"""The detection evaluator: did a confident box of the object's class land on the object?

Per image, the *kept* detections are those scoring at least ``score``; a detection *matches*
when its label is one of the object's classes. The true box is the visible mask's box, taken as
the continuous box [x0, x1] × [y0, y1] in the stored image's pixels.

Besides the per-image verdict, every matching detection (kept or not) is stored with its score
and IoU, so average precision can be computed over any subset of images later, in SQL
(:mod:`sweep3d.results.detection`), without re-running the model.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pyarrow as pa
from pydantic import Field

from sweep3d.stages.infer.evaluators.evaluator import EVALUATORS, Evaluator, EvaluatorParams, IoU, Roles, Truth, box_iou
from sweep3d.stages.infer.labels import LabelMap
from sweep3d.stages.infer.outputs import Detections

DETECTION_FIELDS = [
    ("valid", pa.bool_()),
    ("correct", pa.bool_()),
    ("outcome", pa.string()),
    ("class_correct", pa.bool_()),
    ("iou", pa.float64()),
    ("score", pa.float64()),
    ("pred_x0", pa.float64()),
    ("pred_y0", pa.float64()),
    ("pred_x1", pa.float64()),
    ("pred_y1", pa.float64()),
    ("top1_label", pa.string()),
    ("boxes", pa.int32()),
    ("false_positives", pa.int32()),
    ("det_scores", pa.list_(pa.float32())),
    ("det_ious", pa.list_(pa.float32())),
]


@EVALUATORS.register("detection")
class DetectionEvaluator(Evaluator):
    """Correct when a kept detection of the object's class overlaps the true box with IoU ≥ ``iou``.

    Columns: ``outcome`` (correct, wrong_box: the class found but the box off, wrong_class: a
    kept box of another class on the object, missed); ``class_correct``; the chosen box
    (``pred_*``, its ``score``, ``top1_label``, and ``iou`` when it matches): the best-overlapping
    kept matching box, else the highest-scoring kept box; ``boxes`` kept, ``false_positives``
    (kept boxes other than the true positive); ``det_scores``/``det_ious``: every matching
    detection by score, descending, with its IoU (0 for an image with no visible object).
    """

    class Params(EvaluatorParams):
        iou: IoU = 0.5
        score: float = Field(0.5, ge=0.0, le=1.0, allow_inf_nan=False, description="The score a box needs to count.")

    schema = pa.schema(DETECTION_FIELDS)
    task = "detection"
    passes = ("mask",)
    roles = Roles(outcome="outcome", iou="iou", prediction="top1_label", detection_scores="det_scores",
                  detection_ious="det_ious")

    def measure(self) -> tuple[str, str]:
        return "detection accuracy", f"a kept box of the object's class with IoU ≥ {self.params.iou:g}"

    def evaluate(self, outputs: Sequence[Detections], truths: Sequence[Truth], labels: LabelMap) -> list[dict]:
        return [self._row(found, truth, labels) for found, truth in zip(outputs, truths)]

    def _row(self, found: Detections, truth: Truth, labels: LabelMap) -> dict:
        true_box = truth.box
        ious = box_iou(found.boxes, true_box) if true_box is not None else np.zeros(len(found.scores))
        kept = found.scores >= self.params.score
        matching = np.isin(found.labels, np.asarray(truth.ids, dtype=np.int64))
        hits = np.flatnonzero(kept & matching)
        chosen: int | None = None
        if len(hits):  # the best overlap; among equals the higher score, then the first
            chosen = int(hits[np.lexsort((-found.scores[hits], -ious[hits]))[0]])
        elif kept.any():
            candidates = np.flatnonzero(kept)
            chosen = int(candidates[np.argmax(found.scores[candidates])])
        iou = float(ious[chosen]) if len(hits) and true_box is not None else None
        correct = iou is not None and iou >= self.params.iou
        if true_box is None:
            outcome = "missed"
        elif correct:
            outcome = "correct"
        elif len(hits):
            outcome = "wrong_box"
        elif np.any(kept & ~matching & (ious >= self.params.iou)):
            outcome = "wrong_class"
        else:
            outcome = "missed"
        order = np.flatnonzero(matching)
        order = order[np.argsort(-found.scores[order], kind="stable")]
        box = found.boxes[chosen] if chosen is not None else (None,) * 4
        return {
            "valid": True,
            "correct": correct,
            "outcome": outcome,
            "class_correct": bool(len(hits)),
            "iou": iou,
            "score": float(found.scores[chosen]) if chosen is not None else None,
            **{name: (float(v) if v is not None else None)
               for name, v in zip(("pred_x0", "pred_y0", "pred_x1", "pred_y1"), box)},
            "top1_label": labels.names[int(found.labels[chosen])] if chosen is not None else None,
            "boxes": int(kept.sum()),
            "false_positives": int(kept.sum()) - int(correct),
            "det_scores": [float(s) for s in found.scores[order]],
            "det_ious": [float(v) for v in ious[order]],
        }
