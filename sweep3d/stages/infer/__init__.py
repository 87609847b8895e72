"""Infer: batched model inference and evaluation of each image against its ground truth."""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used.
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

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
