"""The classification evaluator: is the top-1 class one of the object's labels?"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pyarrow as pa

from sweep3d.stages.infer.evaluators.evaluator import (
    EVALUATORS,
    Evaluator,
    EvaluatorParams,
    Roles,
    TopK,
    Truth,
    log_softmax,
)
from sweep3d.stages.infer.labels import LabelMap

#: The columns every evaluator that ranks classes shares (localization adds its box to them).
RANKED_FIELDS = [
    ("valid", pa.bool_()),
    ("correct", pa.bool_()),
    ("top1", pa.int32()),
    ("top1_label", pa.string()),
    ("topk", pa.list_(pa.int32())),
    ("topk_labels", pa.list_(pa.string())),
    ("topk_probs", pa.list_(pa.float32())),
    ("label_prob", pa.float64()),
    ("loss", pa.float64()),
    ("correct_top5", pa.bool_()),
    ("label_ids", pa.list_(pa.int32())),
]


def ranked_rows(logits: np.ndarray, truths: Sequence[Truth], labels: LabelMap, top_k: int) -> list[dict]:
    """The :data:`RANKED_FIELDS` of each image: ``correct`` when the top-1 class is in the truth;
    rows with non-finite logits have ``valid = false`` and nulls."""
    raw = np.asarray(logits, dtype=np.float64)
    logp = log_softmax(raw)
    k = min(top_k, logp.shape[1])
    rows = []
    for scores, row, truth in zip(raw, logp, truths):
        if not np.all(np.isfinite(row)):
            rows.append({"valid": False, **{name: None for name, _ in RANKED_FIELDS[1:]}})
            continue
        # Rank by the logits themselves: log-probabilities can round distinct logits into ties.
        order = np.argsort(-scores, kind="stable")[: max(k, 5)]
        truth_logp = row[list(truth.ids)]
        label_logp = float(truth_logp.max() + np.log(np.exp(truth_logp - truth_logp.max()).sum()))
        rows.append(
            {
                "valid": True,
                "correct": bool(int(order[0]) in truth.ids),
                "top1": int(order[0]),
                "top1_label": labels.names[int(order[0])],
                "topk": [int(i) for i in order[:k]],
                "topk_labels": [labels.names[int(i)] for i in order[:k]],
                "topk_probs": [float(np.exp(row[i])) for i in order[:k]],
                "label_prob": float(np.exp(label_logp)),
                "loss": float(-label_logp),
                "correct_top5": bool(set(int(i) for i in order[:5]) & set(truth.ids)),
                "label_ids": list(truth.ids),
            }
        )
    return rows


@EVALUATORS.register("classification")
class ClassificationEvaluator(Evaluator):
    """Correct when the top-1 class is one of the object's labels.

    Columns: ``correct``; ``top1``/``top1_label``; the top-k class ids, names and probabilities;
    ``label_prob``, the probability of the label set; ``loss`` = -log(label_prob);
    ``correct_top5``, one of the labels among the five highest logits (whatever ``top_k``);
    ``label_ids``, the object's labels as the model's class ids; ``valid`` is false when the
    model returned non-finite outputs (then the rest is null).
    """

    class Params(EvaluatorParams):
        top_k: TopK = 5

    schema = pa.schema(RANKED_FIELDS)
    roles = Roles(loss="loss", prediction="top1_label")

    def measure(self) -> tuple[str, str]:
        return "top-1 accuracy", "the top-1 class is one of the object's labels"

    def evaluate(self, logits: np.ndarray, truths: Sequence[Truth], labels: LabelMap) -> list[dict]:
        return ranked_rows(logits, truths, labels, self.params.top_k)
