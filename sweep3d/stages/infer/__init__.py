"""Infer: batched model inference and evaluation of each image against its ground truth."""

from __future__ import annotations

__all__ = [
    "ClassificationEvaluator", "Classifier", "Detector", "EVALUATORS", "Evaluator", "EvaluatorParams",
    "IMAGENET", "ImageTensors", "InferStage", "LabelMap", "MODELS", "ModelHandle", "ModelInputs", "Normalize",
    "Preprocess", "Roles", "Segmenter", "Truth", "builtin_labels", "builtin_model", "check_task", "choose_backend",
    "evaluate_checked", "evaluator_key", "first_rows", "infer_base", "key_backend", "load_model", "measure_of",
    "model_outputs", "object_class_ids", "padded", "pending_predictions", "pred_keys", "predict"
]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.stages.infer.evaluate import evaluate_checked
    from sweep3d.stages.infer.evaluators import ClassificationEvaluator, measure_of
    from sweep3d.stages.infer.evaluators.evaluator import EVALUATORS, Evaluator, EvaluatorParams, Roles, Truth
    from sweep3d.stages.infer.handle import ModelHandle
    from sweep3d.stages.infer.infer_stage import (
        InferStage,
        ModelInputs,
        first_rows,
        object_class_ids,
        padded,
        pending_predictions,
    )
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
    from sweep3d.stages.infer.prediction_keys import choose_backend, evaluator_key, infer_base, key_backend, pred_keys
    from sweep3d.stages.infer.task_calls import check_task, model_outputs, predict

__getattr__, __dir__ = _exports(__name__, {
    "ClassificationEvaluator": ("sweep3d.stages.infer.evaluators", "ClassificationEvaluator"),
    "Classifier": ("sweep3d.stages.infer.models", "Classifier"),
    "Detector": ("sweep3d.stages.infer.models", "Detector"),
    "EVALUATORS": ("sweep3d.stages.infer.evaluators.evaluator", "EVALUATORS"),
    "Evaluator": ("sweep3d.stages.infer.evaluators.evaluator", "Evaluator"),
    "EvaluatorParams": ("sweep3d.stages.infer.evaluators.evaluator", "EvaluatorParams"),
    "IMAGENET": ("sweep3d.stages.infer.labels", "IMAGENET"),
    "ImageTensors": ("sweep3d.stages.infer.models", "ImageTensors"),
    "InferStage": ("sweep3d.stages.infer.infer_stage", "InferStage"),
    "LabelMap": ("sweep3d.stages.infer.labels", "LabelMap"),
    "MODELS": ("sweep3d.stages.infer.models", "MODELS"),
    "ModelHandle": ("sweep3d.stages.infer.handle", "ModelHandle"),
    "ModelInputs": ("sweep3d.stages.infer.infer_stage", "ModelInputs"),
    "object_class_ids": ("sweep3d.stages.infer.infer_stage", "object_class_ids"),
    "Normalize": ("sweep3d.stages.infer.models", "Normalize"),
    "Preprocess": ("sweep3d.stages.infer.models", "Preprocess"),
    "Roles": ("sweep3d.stages.infer.evaluators.evaluator", "Roles"),
    "Segmenter": ("sweep3d.stages.infer.models", "Segmenter"),
    "Truth": ("sweep3d.stages.infer.evaluators.evaluator", "Truth"),
    "builtin_labels": ("sweep3d.stages.infer.models", "builtin_labels"),
    "builtin_model": ("sweep3d.stages.infer.models", "builtin_model"),
    "check_task": ("sweep3d.stages.infer.task_calls", "check_task"),
    "evaluate_checked": ("sweep3d.stages.infer.evaluate", "evaluate_checked"),
    "evaluator_key": ("sweep3d.stages.infer.prediction_keys", "evaluator_key"),
    "first_rows": ("sweep3d.stages.infer.infer_stage", "first_rows"),
    "infer_base": ("sweep3d.stages.infer.prediction_keys", "infer_base"),
    "key_backend": ("sweep3d.stages.infer.prediction_keys", "key_backend"),
    "choose_backend": ("sweep3d.stages.infer.prediction_keys", "choose_backend"),
    "load_model": ("sweep3d.stages.infer.models", "load_model"),
    "measure_of": ("sweep3d.stages.infer.evaluators", "measure_of"),
    "model_outputs": ("sweep3d.stages.infer.task_calls", "model_outputs"),
    "padded": ("sweep3d.stages.infer.infer_stage", "padded"),
    "pending_predictions": ("sweep3d.stages.infer.infer_stage", "pending_predictions"),
    "pred_keys": ("sweep3d.stages.infer.prediction_keys", "pred_keys"),
    "predict": ("sweep3d.stages.infer.task_calls", "predict"),
})
