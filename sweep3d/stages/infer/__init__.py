"""Infer: batched model inference and evaluation of each image against its ground truth."""

from sweep3d.stages.infer.evaluators import (
           EVALUATORS,
           ClassificationEvaluator,
           Evaluator,
)
from sweep3d.stages.infer.labels import IMAGENET, LabelMap
from sweep3d.stages.infer.models import (
           MODELS,
           Classifier,
           Preprocess,
           load_model,
           model_digest,
)
from sweep3d.stages.infer.stage import infer_stage, predict

__all__ = ["EVALUATORS", "IMAGENET", "MODELS", "ClassificationEvaluator", "Classifier", "Evaluator",
           "LabelMap", "Preprocess", "infer_stage", "load_model", "model_digest", "predict"]
