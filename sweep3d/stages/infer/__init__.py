"""Infer: batched model inference and evaluation of each image against its ground truth."""

from __future__ import annotations

__all__ = ["EVALUATORS", "IMAGENET", "MODELS", "ClassificationEvaluator", "Classifier", "Detector", "Evaluator", "EvaluatorParams", "ImageTensors", "InferStage",
           "LabelMap", "ModelHandle", "Normalize", "Preprocess", "Segmenter", "builtin_labels", "builtin_model", "load_model", "pending_predictions", "predict", "Roles"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.lazy import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.stages.infer.evaluators import EVALUATORS, ClassificationEvaluator, Evaluator, EvaluatorParams, Roles
    from sweep3d.stages.infer.handle import ModelHandle
    from sweep3d.stages.infer.labels import IMAGENET, LabelMap
    from sweep3d.stages.infer.models import (
        MODELS,
        Classifier,
        Detector,
        ImageTensors,
        Normalize,
        Preprocess,
        Segmenter,
        builtin_labels,
        builtin_model,
        load_model,
    )
    from sweep3d.stages.infer.stage import InferStage, pending_predictions
    from sweep3d.stages.infer.tasks import predict

__getattr__, __dir__ = _exports(__name__, {
    'ClassificationEvaluator': ('sweep3d.stages.infer.evaluators', 'ClassificationEvaluator'),
    'Classifier': ('sweep3d.stages.infer.models', 'Classifier'),
    'Detector': ('sweep3d.stages.infer.models', 'Detector'),
    'EVALUATORS': ('sweep3d.stages.infer.evaluators', 'EVALUATORS'),
    'Evaluator': ('sweep3d.stages.infer.evaluators', 'Evaluator'),
    'EvaluatorParams': ('sweep3d.stages.infer.evaluators', 'EvaluatorParams'),
    'IMAGENET': ('sweep3d.stages.infer.labels', 'IMAGENET'),
    'ImageTensors': ('sweep3d.stages.infer.models', 'ImageTensors'),
    'InferStage': ('sweep3d.stages.infer.stage', 'InferStage'),
    'LabelMap': ('sweep3d.stages.infer.labels', 'LabelMap'),
    'MODELS': ('sweep3d.stages.infer.models', 'MODELS'),
    'ModelHandle': ('sweep3d.stages.infer.handle', 'ModelHandle'),
    'Normalize': ('sweep3d.stages.infer.models', 'Normalize'),
    'Preprocess': ('sweep3d.stages.infer.models', 'Preprocess'),
    'Roles': ('sweep3d.stages.infer.evaluators', 'Roles'),
    'Segmenter': ('sweep3d.stages.infer.models', 'Segmenter'),
    'builtin_labels': ('sweep3d.stages.infer.models', 'builtin_labels'),
    'builtin_model': ('sweep3d.stages.infer.models', 'builtin_model'),
    'load_model': ('sweep3d.stages.infer.models', 'load_model'),
    'pending_predictions': ('sweep3d.stages.infer.stage', 'pending_predictions'),
    'predict': ('sweep3d.stages.infer.tasks', 'predict'),
})
