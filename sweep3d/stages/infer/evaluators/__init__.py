"""Evaluators: a model's outputs and each image's ground truth in, result columns out.

Each task is a module that registers its evaluator; a user's own is named ``module:Class``.
"""

from sweep3d.stages.infer.evaluators.classification import ClassificationEvaluator
from sweep3d.stages.infer.evaluators.detection import DetectionEvaluator
from sweep3d.stages.infer.evaluators.evaluator import (
    EVALUATORS,
    OUTCOMES,
    TASKS,
    Evaluator,
    EvaluatorParams,
    Roles,
    Truth,
    box_iou,
    log_softmax,
)
from sweep3d.stages.infer.evaluators.localization import LocalizationEvaluator
from sweep3d.stages.infer.evaluators.segmentation import SegmentationEvaluator


def measure_of(settings: object) -> tuple[str, str]:
    """What the spec's ``[evaluator]`` (its settings) calls correct: ``("localization accuracy",
    "top-1 class right and box IoU ≥ 0.5")``; a plain "accuracy" when the evaluator cannot be made
    (a plug-in that no longer imports: the results still read)."""
    try:
        return EVALUATORS.get(settings.kind).from_settings(settings).measure()
    except Exception:  # noqa: BLE001 - a headline is no place for a plug-in's error
        return "accuracy", "the evaluator's correct"

__all__ = ["EVALUATORS", "OUTCOMES", "TASKS", "ClassificationEvaluator", "DetectionEvaluator", "Evaluator",
           "EvaluatorParams", "LocalizationEvaluator", "Roles", "SegmentationEvaluator", "Truth", "box_iou", "log_softmax",
           "measure_of"]
