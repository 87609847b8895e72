"""The localization evaluator: ImageNet's localization task, one object per image.

Correct when the top-1 class is one of the object's labels *and* the predicted box overlaps the
object's true box (the box of its visible pixels, from the mask pass) with IoU ≥ ``iou``.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pyarrow as pa

from sweep3d.stages.infer.evaluators.classification import RANKED_FIELDS, ranked_rows
from sweep3d.stages.infer.evaluators.evaluator import (
    EVALUATORS,
    Evaluator,
    EvaluatorParams,
    IoU,
    Roles,
    TopK,
    Truth,
    box_iou,
)
from sweep3d.stages.infer.labels import LabelMap
from sweep3d.stages.infer.outputs import Localized

#: The columns of a task that predicts one box: what went wrong, the class and the box.
BOX_FIELDS = [
    ("outcome", pa.string()),
    ("class_correct", pa.bool_()),
    ("iou", pa.float64()),
    ("pred_x0", pa.float64()),
    ("pred_y0", pa.float64()),
    ("pred_x1", pa.float64()),
    ("pred_y1", pa.float64()),
]


@EVALUATORS.register("localization")
class LocalizationEvaluator(Evaluator):
    """Top-1 class in the labels and IoU(predicted box, true box) ≥ ``iou``.

    Columns: the classification columns (``correct`` is the localization's), and ``outcome``
    ("correct", "wrong_class", "wrong_box", or "missed" when the model gave no box or nothing of
    the object is visible), ``class_correct``, ``iou`` and the predicted box ``pred_x0 … pred_y1``
    in the stored image's pixels.
    """

    class Params(EvaluatorParams):
        top_k: TopK = 5
        iou: IoU = 0.5

    schema = pa.schema(RANKED_FIELDS + BOX_FIELDS)
    task = "localization"
    passes = ("mask",)
    roles = Roles(loss="loss", outcome="outcome", iou="iou", prediction="top1_label")

    def measure(self) -> tuple[str, str]:
        return "localization accuracy", f"top-1 class right and box IoU ≥ {self.params.iou:g}"

    def evaluate(self, outputs: Localized, truths: Sequence[Truth], labels: LabelMap) -> list[dict]:
        rows = ranked_rows(outputs.logits, truths, labels, self.params.top_k)
        for row, box, truth in zip(rows, np.asarray(outputs.boxes, np.float64), truths):
            if not row["valid"]:
                row.update({name: None for name, _ in BOX_FIELDS})
                continue
            found, true_box = bool(np.isfinite(box).all()), truth.box
            iou = float(box_iou(box, true_box)[0]) if found and true_box is not None else None
            class_correct = row["correct"]
            row.update(class_correct=class_correct, iou=iou,
                       **dict(zip(("pred_x0", "pred_y0", "pred_x1", "pred_y1"),
                                  (float(v) for v in box) if found else (None,) * 4)))
            row["correct"] = bool(class_correct and iou is not None and iou >= self.params.iou)
            row["outcome"] = ("wrong_class" if not class_correct else "missed" if iou is None
                              else "correct" if row["correct"] else "wrong_box")
        return rows
