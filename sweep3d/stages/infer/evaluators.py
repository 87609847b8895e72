"""Evaluators turn a model's outputs and a job's ground truth into result columns.

Each evaluator declares its columns (a pyarrow schema) before it runs; the predictions table
is written with that schema.
"""

from __future__ import annotations

from typing import ClassVar, Sequence

import numpy as np
import pyarrow as pa

from sweep3d.registry import Registry
from sweep3d.stages.infer.labels import LabelMap

EVALUATORS: Registry[type["Evaluator"]] = Registry("evaluator")


class Evaluator:
    """Base of evaluators: ``schema`` lists the columns ``evaluate`` returns, one row per image."""

    schema: ClassVar[pa.Schema]
    #: Render passes the evaluator needs beside the image ("mask", "depth"; see ``sweep3d.truth``).
    passes: ClassVar[tuple[str, ...]] = ()

    def __init__(self, top_k: int = 5) -> None:
        self.top_k = top_k

    def evaluate(self, logits: np.ndarray, truths: Sequence[tuple[int, ...]], labels: LabelMap) -> list[dict]:
        raise NotImplementedError


def log_softmax(logits: np.ndarray) -> np.ndarray:
    """Numerically stable log-softmax over the last axis, computed in float64.

    Args:
        logits: float array (N, C); rows with non-finite values give NaN rows (flagged invalid).
    """
    x = np.asarray(logits, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):  # inf - inf: a NaN row, flagged, not a warning
        shifted = x - x.max(axis=-1, keepdims=True)
        return shifted - np.log(np.exp(shifted).sum(axis=-1, keepdims=True))


@EVALUATORS.register("classification")
class ClassificationEvaluator(Evaluator):
    """Correct when the top-1 class is one of the object's labels.

    Columns: ``correct``; ``top1``/``top1_label``; the top-k class ids, names and probabilities;
    ``label_prob``, the probability of the label set; ``loss`` = -log(label_prob); ``valid``
    is false when the model returned non-finite outputs (then correct/loss are null).
    """

    schema = pa.schema(
        [
            ("valid", pa.bool_()),
            ("correct", pa.bool_()),
            ("top1", pa.int32()),
            ("top1_label", pa.string()),
            ("topk", pa.list_(pa.int32())),
            ("topk_labels", pa.list_(pa.string())),
            ("topk_probs", pa.list_(pa.float32())),
            ("label_prob", pa.float64()),
            ("loss", pa.float64()),
        ]
    )

    def evaluate(self, logits: np.ndarray, truths: Sequence[tuple[int, ...]], labels: LabelMap) -> list[dict]:
        raw = np.asarray(logits, dtype=np.float64)
        logp = log_softmax(raw)
        k = min(self.top_k, logp.shape[1])
        rows = []
        for scores, row, truth in zip(raw, logp, truths):
            if not np.all(np.isfinite(row)):
                rows.append({"valid": False, "correct": None, "top1": None, "top1_label": None, "topk": None,
                             "topk_labels": None, "topk_probs": None, "label_prob": None, "loss": None})
                continue
            # Rank by the logits themselves: log-probabilities can round distinct logits into ties.
            order = np.argsort(-scores, kind="stable")[:k]
            truth_logp = row[list(truth)]
            label_logp = float(truth_logp.max() + np.log(np.exp(truth_logp - truth_logp.max()).sum()))
            rows.append(
                {
                    "valid": True,
                    "correct": bool(int(order[0]) in truth),
                    "top1": int(order[0]),
                    "top1_label": labels.names[int(order[0])],
                    "topk": [int(i) for i in order],
                    "topk_labels": [labels.names[int(i)] for i in order],
                    "topk_probs": [float(np.exp(row[i])) for i in order],
                    "label_prob": float(np.exp(label_logp)),
                    "loss": float(-label_logp),
                }
            )
        return rows
