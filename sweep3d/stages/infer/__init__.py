"""Infer: batched model inference and evaluation of each image against its ground truth."""

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

__all__ = ["EVALUATORS", "IMAGENET", "MODELS", "ClassificationEvaluator", "Classifier", "Detector", "Evaluator", "EvaluatorParams", "ImageTensors", "InferStage",
           "LabelMap", "ModelHandle", "Normalize", "Preprocess", "Segmenter", "builtin_labels", "builtin_model", "load_model", "pending_predictions", "predict", "Roles"]

