"""The infer stage: batched forward passes over every image whose prediction is not cached."""

from __future__ import annotations

import os
import time
from typing import Callable

import numpy as np
import pyarrow as pa

from sweep3d.cache.store import Store, utc_now
from sweep3d.errors import UserError
from sweep3d.pixels import decode_png
from sweep3d.progress import RunProgress
from sweep3d.stages.infer.evaluators import EVALUATORS, Evaluator
from sweep3d.stages.infer.models import Classifier, load_model
from sweep3d.stages.outcome import StageOutcome
from sweep3d.stages.plan.jobs import Job, Plan

BASE_COLUMNS = [("pred_key", pa.string()), ("image_key", pa.string()), ("model", pa.string()),
                ("model_digest", pa.string()), ("seconds", pa.float64()),
                ("created_at", pa.timestamp("us"))]


def predictions_schema(evaluator: Evaluator) -> pa.Schema:
    return pa.schema(BASE_COLUMNS + list(zip(evaluator.schema.names, evaluator.schema.types)))


def predict(model: Classifier, images: np.ndarray, runner: Callable | None = None) -> np.ndarray:
    """Logits of a batch.

    Args:
        images: float32 (N, H, W, 3) in [0, 1].
        runner: runs the preprocessed batch instead of the torch module (e.g. ONNX Runtime).
    Returns:
        float32 (N, C) logits.
    Raises:
        UserError: if the model's output is not (N, C).
    """
    import torch

    with torch.inference_mode():
        batch = model.preprocess(images)
        out = torch.from_numpy(runner(batch)) if runner is not None else model.module(batch)
    if isinstance(out, (tuple, list)):
        out = out[0]
    if not isinstance(out, torch.Tensor) or out.ndim != 2 or out.shape[0] != len(images):
        shape = tuple(out.shape) if isinstance(out, torch.Tensor) else type(out).__name__
        raise UserError(f"the model must return logits of shape (batch, classes); got {shape}")
    return out.detach().float().cpu().numpy()


def infer_stage(plan: Plan, store: Store, progress: RunProgress) -> StageOutcome:
    started = time.perf_counter()
    spec = plan.spec.spec
    unique: dict[str, Job] = {}
    for job in plan.jobs:
        unique.setdefault(job.pred_key, job)
    cached = store.keys("predictions") & set(unique)
    images = store.keys("images") | store.keys("renders")
    todo = [j for k, j in unique.items() if k not in cached and j.image_key in images
            and store.blob_path(j.image_key).exists()]
    outcome = StageOutcome("infer", total=len(unique), cached=len(cached),
                           skipped=len(unique) - len(cached) - len(todo))
    if todo:
        import torch

        threads = spec.model.threads or os.cpu_count() or 1
        torch.set_num_threads(threads)
        model = load_model(spec.model.name)
        runner = None
        if spec.model.backend == "onnx":
            from sweep3d.stages.infer.onnx_backend import OnnxRunner

            runner = OnnxRunner(model, store.root / "models", plan.model_digest, threads)
        labels = model.label_map()
        evaluator = EVALUATORS.get(spec.evaluator.kind)(top_k=spec.evaluator.top_k)
        truths = _truths(plan, labels)
        schema = predictions_schema(evaluator)
        size = spec.model.batch_size
        with progress.stage("infer", len(todo), len(cached)) as bar, \
                store.segment_writer("predictions", schema) as writer:
            for start in range(0, len(todo), size):
                batch = todo[start : start + size]
                t0 = time.perf_counter()
                pixels = np.stack([decode_png(store.blob_path(j.image_key)) for j in batch])
                logits = predict(model, pixels, runner)
                if logits.shape[1] != len(labels):
                    raise UserError(f"model {spec.model.name!r} returns {logits.shape[1]} classes "
                                    f"but its label map has {len(labels)}")
                rows = evaluator.evaluate(logits, [truths[j.object] for j in batch], labels)
                per_image = (time.perf_counter() - t0) / len(batch)
                now = utc_now()
                for job, row in zip(batch, rows):
                    writer.add({"pred_key": job.pred_key, "image_key": job.image_key, "model": spec.model.name,
                                "model_digest": plan.model_digest, "seconds": per_image, "created_at": now, **row})
                outcome.computed += len(batch)
                bar.advance(len(batch))
    outcome.seconds = time.perf_counter() - started
    return outcome


def _truths(plan: Plan, labels) -> dict[str, tuple[int, ...]]:
    """Ground-truth class ids per object, in the model's label space."""
    out = {}
    for i, obj in enumerate(plan.spec.spec.objects):
        try:
            out[obj.name] = tuple(sorted({labels.index(label) for label in obj.labels}))
        except ValueError as exc:
            raise UserError(f"{plan.spec.path}: objects[{i}].labels: {exc}") from None
    return out
