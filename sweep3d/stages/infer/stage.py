"""The infer stage: batched forward passes over every image whose prediction is not cached.

A prediction is valid only if its image was valid (no NaN/inf in the render or after post
controls) and the model's outputs are finite; an invalid image is not shown to the model and
gets a row with ``valid = false``, so it is counted as invalid and never averaged. An image blob
that is missing or damaged is discarded so the next pass of the run computes it again.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pyarrow as pa

from sweep3d.cache.blobs import load_image
from sweep3d.cache.store import Store, utc_now
from sweep3d.errors import SpecError, UserError
from sweep3d.progress import RunProgress
from sweep3d.spec.framing import resolve_framing
from sweep3d.stages.infer.evaluators import EVALUATORS, Evaluator
from sweep3d.stages.infer.labels import LabelMap
from sweep3d.stages.infer.models import Classifier, for_model_framing, load_model
from sweep3d.stages.outcome import StageOutcome
from sweep3d.stages.plan.jobs import Job, Plan

BASE_COLUMNS = [("pred_key", pa.string()), ("image_key", pa.string()), ("model", pa.string()),
                ("model_digest", pa.string()), ("seconds", pa.float64()),
                ("created_at", pa.timestamp("us"))]


def predictions_schema(evaluator: Evaluator) -> pa.Schema:
    return pa.schema(BASE_COLUMNS + list(zip(evaluator.schema.names, evaluator.schema.types)))


def predict(model: Classifier, images: np.ndarray, name: str = "the model", runner: Callable | None = None) -> np.ndarray:
    """Logits of a batch.

    Args:
        images: float32 (N, H, W, 3) in [0, 1].
        name: the model's name in the spec, for error messages.
        runner: runs the preprocessed batch instead of the torch module (e.g. ONNX Runtime).
    Returns:
        float32 (N, C) logits.
    Raises:
        UserError: if the model raises or its output is not (N, C).
    """
    import torch

    try:
        with torch.inference_mode():
            batch = model.preprocess(images)
            out = torch.from_numpy(runner(batch)) if runner is not None else model.module(batch)
    except Exception as exc:  # noqa: BLE001  (a user's model failing on its input is a user error)
        detail = " ".join(str(exc).split())[:300]
        raise UserError(f"model {name!r} raised {type(exc).__name__} on a batch of shape {tuple(images.shape)}: "
                        f"{detail}; fix the model or its preprocessing") from None
    if isinstance(out, (tuple, list)):
        out = out[0]
    if not isinstance(out, torch.Tensor) or out.ndim != 2 or out.shape[0] != len(images):
        shape = tuple(out.shape) if isinstance(out, torch.Tensor) else type(out).__name__
        raise UserError(f"the model must return logits of shape (batch, classes); got {shape}")
    return out.detach().float().cpu().numpy()


@dataclass
class ReadyModel:
    """A model loaded and checked against the spec: its label map and each object's true classes."""

    model: Classifier
    labels: LabelMap
    truths: dict[str, tuple[int, ...]]
    runner: Callable | None = None  # another backend (ONNX Runtime), checked against torch


def pending_predictions(plan: Plan, store: Store) -> set[str]:
    """Prediction keys of the plan that the store lacks."""
    return {j.pred_key for j in plan.jobs} - store.keys("predictions")


def prepare_model(plan: Plan, store: Store | None = None) -> ReadyModel:
    """Load the spec's model and try it on one blank image, so that a broken model, a wrong
    output shape or a label it lacks fails in seconds, before anything is rendered.

    Raises:
        SpecError: naming ``model.name`` or the object's labels, with the fix.
    """
    import torch

    spec = plan.spec
    name = spec.spec.model.name
    threads = spec.spec.model.threads or os.cpu_count() or 1
    torch.set_num_threads(threads)
    framing = plan.framing or resolve_framing(spec)
    try:
        model = load_model(name)
        if framing.model:  # the image is the model's input already: no resize or crop again
            model.preprocess = for_model_framing(model.preprocess, name)
        labels = model.label_map()
        size = framing.crop
        logits = predict(model, np.zeros((1, size, size, 3), np.float32), name)
        _check_classes(logits, labels, name)
    except SpecError:
        raise
    except UserError as exc:
        raise SpecError(str(spec.path), "model.name", str(exc)) from None
    runner = None
    if spec.spec.model.backend == "onnx":
        from sweep3d.stages.infer.onnx_backend import OnnxRunner

        runner = OnnxRunner(model, Store(spec.store if store is None else store.root).root / "models",
                            plan.model_digest, threads)
    return ReadyModel(model, labels, _truths(plan, labels), runner)


def infer_stage(plan: Plan, store: Store, progress: RunProgress, model: ReadyModel | None = None,
                on_ray: bool = False) -> StageOutcome:
    """Predict every image of the plan that has no prediction yet.

    Args:
        model: the model from :func:`prepare_model`; loaded here when None and needed.
    """
    started = time.perf_counter()
    spec = plan.spec.spec
    unique: dict[str, Job] = {}
    for job in plan.jobs:
        unique.setdefault(job.pred_key, job)
    cached = store.keys("predictions") & set(unique)
    available = {"images": store.keys("images"), "renders": store.keys("renders")}
    todo = [j for k, j in unique.items() if k not in cached and j.image_key in available[_table(j)]
            and store.blob_path(j.image_key).exists()]
    outcome = StageOutcome("infer", total=len(unique), cached=len(cached),
                           skipped=len(unique) - len(cached) - len(todo))
    if todo:
        ready = model or prepare_model(plan, store)
        remote = None
        if on_ray and spec.model.backend == "torch":  # batches go to an inference actor (GPU if any)
            from sweep3d.stages.infer.ray_actor import remote_runner

            remote = remote_runner(spec.model.name, bool(plan.framing and plan.framing.model))
        evaluator = EVALUATORS.get(spec.evaluator.kind)(top_k=spec.evaluator.top_k)
        schema = predictions_schema(evaluator)
        valid = {**store.column_map("renders", "valid"), **store.column_map("images", "valid")}
        digests = {t: store.digests(t) for t in available}
        damaged: dict[str, set[str]] = {t: set() for t in available}
        size = spec.model.batch_size
        with progress.stage("infer", len(todo), len(cached)) as bar, \
                store.segment_writer("predictions", schema) as writer:
            for start in range(0, len(todo), size):
                t0 = time.perf_counter()
                batch, pixels, invalid = [], [], []
                for job in todo[start : start + size]:
                    if valid.get(job.image_key) is False:  # NaN/inf upstream: not shown to the model
                        invalid.append(job)
                        continue
                    image = load_image(store, job.image_key, digests[_table(job)].get(job.image_key))
                    if image is None:  # damaged: discarded below, recomputed by the next pass
                        damaged[_table(job)].add(job.image_key)
                        outcome.skipped += 1
                        continue
                    batch.append(job)
                    pixels.append(image)
                rows = []
                if batch:
                    stacked = np.stack(pixels)
                    logits = remote(stacked) if remote is not None else predict(
                        ready.model, stacked, spec.model.name, ready.runner)
                    _check_classes(logits, ready.labels, spec.model.name)
                    rows = evaluator.evaluate(logits, [ready.truths[j.object] for j in batch], ready.labels)
                per_image = (time.perf_counter() - t0) / max(len(batch) + len(invalid), 1)
                now = utc_now()
                for job, row in [*zip(batch, rows), *((j, _invalid_row(schema)) for j in invalid)]:
                    writer.add({"pred_key": job.pred_key, "image_key": job.image_key, "model": spec.model.name,
                                "model_digest": plan.model_digest, "seconds": per_image, "created_at": now, **row})
                outcome.computed += len(batch) + len(invalid)
                bar.advance(len(todo[start : start + size]))
        for table, keys in damaged.items():
            store.discard(table, keys, "are damaged (digest mismatch or undecodable)")
    outcome.seconds = time.perf_counter() - started
    return outcome


def _table(job: Job) -> str:
    """The table whose row describes the image this job's model sees."""
    return "renders" if job.image_key == job.render_key else "images"


def _invalid_row(schema: pa.Schema) -> dict:
    """Evaluator columns for an image with NaN/inf pixels: valid = false, everything else null."""
    row = {name: None for name in schema.names if name not in dict(BASE_COLUMNS)}
    if "valid" in row:
        row["valid"] = False
    return row


def _check_classes(logits: np.ndarray, labels: LabelMap, name: str) -> None:
    if logits.shape[1] != len(labels):
        raise UserError(f"model {name!r} returns {logits.shape[1]} classes but its label map has {len(labels)}; "
                        "return one logit per class, or give the Classifier its own labels")


def _truths(plan: Plan, labels) -> dict[str, tuple[int, ...]]:
    """Ground-truth class ids per object, in the model's label space."""
    out = {}
    for i, obj in enumerate(plan.spec.spec.objects):
        for j, label in enumerate(obj.labels):
            try:
                labels.index(label)
            except ValueError as exc:
                raise SpecError(str(plan.spec.path), f"objects[{i}].labels[{j}]",
                                f"{exc} (the classes of model {plan.spec.spec.model.name!r})") from None
        out[obj.name] = tuple(sorted({labels.index(label) for label in obj.labels}))
    return out
