"""The segmentation evaluator: does the predicted object mask cover the object's visible pixels?

A pixel is predicted as the object when its argmax class is one of the object's classes; the
predicted mask is then compared with the visible mask from the render's mask pass.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pyarrow as pa

from sweep3d.core import encode_mask
from sweep3d.stages.infer.evaluators.evaluator import EVALUATORS, Evaluator, EvaluatorParams, IoU, Roles, Truth
from sweep3d.stages.infer.labels import LabelMap

SEGMENTATION_FIELDS = [
    ("valid", pa.bool_()),
    ("correct", pa.bool_()),
    ("outcome", pa.string()),
    ("class_correct", pa.bool_()),
    ("iou", pa.float64()),
    ("pred_pixels", pa.int64()),
    ("true_pixels", pa.int64()),
    ("top1_label", pa.string()),
    ("pred_mask", pa.binary()),
]


@EVALUATORS.register("segmentation")
class SegmentationEvaluator(Evaluator):
    """Correct when the predicted object mask has IoU ≥ ``iou`` with the visible mask.

    Columns: ``outcome`` (correct; missed: no pixel predicted as the object; wrong_class: the
    class most pixels of the object got is not the object's; wrong_box: the class right, the
    mask off); ``class_correct``; ``iou`` (null when both masks are empty); pixel counts;
    ``top1_label``, the most frequent class over the object's pixels (over the whole image when
    it is hidden); ``pred_mask`` as PNG bytes. ``valid`` is false, and the rest null, for an
    image whose scores are not all finite.
    """

    class Params(EvaluatorParams):
        iou: IoU = 0.5

    schema = pa.schema(SEGMENTATION_FIELDS)
    task = "segmentation"
    passes = ("mask",)
    roles = Roles(outcome="outcome", iou="iou", prediction="top1_label")

    def measure(self) -> tuple[str, str]:
        return "segmentation accuracy", f"predicted object mask IoU ≥ {self.params.iou:g}"

    def evaluate(self, scores: np.ndarray, truths: Sequence[Truth], labels: LabelMap) -> list[dict]:
        return [self._row(image, truth, labels) for image, truth in zip(np.asarray(scores), truths)]

    def _row(self, scores: np.ndarray, truth: Truth, labels: LabelMap) -> dict:
        if not np.all(np.isfinite(scores)):
            return {"valid": False, **{name: None for name, _ in SEGMENTATION_FIELDS[1:]}}
        classes = scores.argmax(axis=0)
        true = truth.mask if truth.mask is not None else np.zeros(classes.shape, dtype=bool)
        if true.shape != classes.shape:
            raise ValueError(f"scores are {classes.shape} pixels but the mask is {true.shape}")
        ids = np.asarray(truth.ids, dtype=np.int64)
        pred = np.isin(classes, ids)
        union = int(np.count_nonzero(pred | true))
        iou = int(np.count_nonzero(pred & true)) / union if union else None
        # Ties between classes name the lowest id, so the label is the same on every run.
        votes = np.bincount((classes[true] if true.any() else classes).ravel(), minlength=scores.shape[0])
        top1 = int(votes.argmax())
        correct = iou is not None and iou >= self.params.iou
        if correct:
            outcome = "correct"
        elif not pred.any():
            outcome = "missed"
        elif top1 not in truth.ids:
            outcome = "wrong_class"
        else:
            outcome = "wrong_box"
        return {
            "valid": True,
            "correct": correct,
            "outcome": outcome,
            "class_correct": top1 in truth.ids,
            "iou": iou,
            "pred_pixels": int(np.count_nonzero(pred)),
            "true_pixels": int(np.count_nonzero(true)),
            "top1_label": labels.names[top1],
            "pred_mask": encode_mask(pred),
        }
