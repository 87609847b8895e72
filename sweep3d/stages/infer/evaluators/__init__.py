"""Evaluators: a model's outputs and each image's ground truth in, result columns out.

Each task is a module that registers its evaluator; a user's own is named ``module:Class``.
"""

from sweep3d.stages.infer.evaluators.base import (
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
from sweep3d.stages.infer.evaluators.classification import ClassificationEvaluator
from sweep3d.stages.infer.evaluators.detection import DetectionEvaluator
from sweep3d.stages.infer.evaluators.localization import LocalizationEvaluator
from sweep3d.stages.infer.evaluators.segmentation import SegmentationEvaluator

__all__ = ["EVALUATORS", "OUTCOMES", "TASKS", "ClassificationEvaluator", "DetectionEvaluator", "Evaluator",
           "EvaluatorParams", "LocalizationEvaluator", "Roles", "SegmentationEvaluator", "Truth", "box_iou", "log_softmax"]
