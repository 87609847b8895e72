"""What every evaluator shares: the registry, the base class, and the ground truth it is handed.

An evaluator turns one batch of a model's outputs and the batch's ground truth into result
columns. It declares, before anything runs:

- ``schema``: the columns it returns (the predictions table is written with them);
- ``task``: what it needs the model to return (see :mod:`sweep3d.stages.infer.outputs`):
  ``"classification"`` logits, ``"localization"`` logits and one box per image,
  ``"detection"`` boxes, labels and scores, ``"segmentation"`` per-pixel class scores, or
  ``"raw"`` the model's output array as it is (a user's own task, e.g. depth estimation);
- ``passes``: the render passes it reads ("mask", "depth"); they are rendered only then, and
  arrive in :class:`Truth` as arrays in the stored image's pixel grid;
- ``Params``: its settings, a :class:`~sweep3d.core.evaluation.EvaluatorParams` model read from the
  spec's ``[evaluator]`` table (besides ``kind``, ``passes`` and ``min_visible``, which every
  evaluator shares); unknown keys are spec errors;
- ``roles``: which of its columns is the verdict, the loss, the outcome, … (a
  :class:`~sweep3d.core.evaluation.Roles`), checked against ``schema`` when the spec loads; the views
  and the report show what the roles say the evaluator has.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, ClassVar, Sequence

import numpy as np
import pyarrow as pa
from pydantic import Field

from sweep3d.core import OUTCOMES, EvaluatorParams, EvaluatorRecord, Registry, Roles
from sweep3d.stages.infer.labels import LabelMap

EVALUATORS: Registry[type["Evaluator"]] = Registry("evaluator")

__all__ = ["EVALUATORS", "OUTCOMES", "TASKS", "Evaluator", "EvaluatorParams", "IoU", "Roles", "TopK", "Truth",
           "box_iou", "log_softmax"]

#: The settings the built-in evaluators share, declared once.
TopK = Annotated[int, Field(ge=1, le=100, description="How many ranked classes the rows keep.")]
IoU = Annotated[float, Field(gt=0.0, le=1.0, allow_inf_nan=False,
                             description="The IoU with the true box or mask that counts as correct.")]

#: What an evaluator's ``task`` may ask the model for (``stages.infer.tasks.model_outputs``).
TASKS = ("classification", "localization", "detection", "segmentation", "raw")


@dataclass(frozen=True, eq=False)
class Truth:
    """One image's ground truth, as an evaluator gets it.

    Attributes:
        ids: the object's classes, as ids of the model's label map.
        mask: the object's visible pixels, bool (H, W) in the stored image's grid; None unless
            the evaluator declares the ``mask`` pass.
        depth: distance along the camera axis, float32 (H, W), ``inf`` where nothing is hit;
            None unless the evaluator declares the ``depth`` pass.
    """

    ids: tuple[int, ...]
    mask: np.ndarray | None = None
    depth: np.ndarray | None = None

    @property
    def box(self) -> tuple[int, int, int, int] | None:
        """The mask's box ``(x0, y0, x1, y1)`` in pixels (x1, y1 exclusive); None without a mask
        or when no pixel of the object is visible."""
        if self.mask is None:
            return None
        from sweep3d.core import box

        return box(self.mask)


class Evaluator:
    """Base of evaluators: ``evaluate`` returns one row (a dict over ``schema``'s names) per image.

    Args:
        params: its settings (a ``Params``); or, instead, their values by name
            (``ClassificationEvaluator(top_k=3)``).
    """

    schema: ClassVar[pa.Schema]
    task: ClassVar[str] = "classification"
    passes: ClassVar[tuple[str, ...]] = ()
    Params: ClassVar[type[EvaluatorParams]] = EvaluatorParams
    roles: ClassVar[Roles] = Roles()

    def __init__(self, params: EvaluatorParams | None = None, **values: Any) -> None:
        self.params = params if params is not None else self.Params(**values)

    @classmethod
    def from_settings(cls, settings: Any) -> "Evaluator":
        """The evaluator configured by the spec's ``[evaluator]`` table (an ``EvaluatorSpec``)."""
        return cls(cls.Params(**settings.params))

    @classmethod
    def record(cls, kind: str) -> EvaluatorRecord:
        """What a plan records of the evaluator called ``kind``: its columns and their roles."""
        return EvaluatorRecord(kind, tuple(cls.schema.names), cls.roles)

    @classmethod
    def where(cls) -> str:
        """Where its ``evaluate`` is written (``mymod.py:12``), for errors that name the plug-in."""
        try:
            lines = inspect.getsourcelines(cls.evaluate)
            return f"{Path(inspect.getsourcefile(cls.evaluate) or '?').name}:{lines[1]}"
        except (OSError, TypeError):
            return cls.__module__

    def key_part(self) -> dict[str, Any]:
        """What of the evaluator's settings changes its rows (part of prediction keys): every
        setting of its ``Params``, by default."""
        return self.params.model_dump(mode="json")

    def measure(self) -> tuple[str, str]:
        """What its ``correct`` measures, for headlines that must not say a bare "accuracy" of a
        box task: a name ("localization accuracy") and the rule ("top-1 class right and box IoU ≥ 0.5")."""
        return "accuracy", f"{type(self).__name__}'s correct"

    def evaluate(self, outputs: Any, truths: Sequence[Truth], labels: LabelMap) -> list[dict]:
        raise NotImplementedError


def box_iou(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> np.ndarray:
    """IoU of boxes ``a`` (N, 4) against one box ``b`` (4,), as float64 (N,); boxes are
    ``(x0, y0, x1, y1)`` in continuous pixel coordinates. An empty union gives 0."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(4)
    w = np.clip(np.minimum(a[:, 2], b[2]) - np.maximum(a[:, 0], b[0]), 0, None)
    h = np.clip(np.minimum(a[:, 3], b[3]) - np.maximum(a[:, 1], b[1]), 0, None)
    inter = w * h
    area_a = np.clip(a[:, 2] - a[:, 0], 0, None) * np.clip(a[:, 3] - a[:, 1], 0, None)
    area_b = max(b[2] - b[0], 0.0) * max(b[3] - b[1], 0.0)
    union = area_a + area_b - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def log_softmax(logits: np.ndarray) -> np.ndarray:
    """Numerically stable log-softmax over the last axis, computed in float64.

    Args:
        logits: float array (N, C); rows with non-finite values give NaN rows (flagged invalid).
    """
    x = np.asarray(logits, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):  # inf - inf: a NaN row, flagged, not a warning
        shifted = x - x.max(axis=-1, keepdims=True)
        return shifted - np.log(np.exp(shifted).sum(axis=-1, keepdims=True))
