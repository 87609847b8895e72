"""The infer stage: batched forward passes over every image whose prediction is not cached.

A prediction is valid only if its image was valid (no NaN/inf in the render or after post
controls) and the model's outputs are finite; an invalid image is not shown to the model and
gets a row with ``valid = false``, so it is counted as invalid and never averaged. An image blob
that is missing or damaged is discarded so the next pass of the run computes it again.
"""

from __future__ import annotations

import os
import time
from typing import Callable, Iterator

import numpy as np
import pyarrow as pa

from sweep3d.cache.blobs import load_image
from sweep3d.cache.store import Store, utc_now
from sweep3d.errors import SpecError, UserError
from sweep3d.spec.columns import PREDICTION_COLUMNS
from sweep3d.stages.driver import Computed
from sweep3d.stages.infer.evaluators import EVALUATORS, Evaluator
from sweep3d.stages.infer.handle import ModelHandle
from sweep3d.stages.infer.labels import LabelMap
from sweep3d.stages.infer.models import Classifier
from sweep3d.stages.jobs import Job, Plan

#: The bookkeeping columns of every prediction row (named in ``spec.columns``, which reserves them).
BASE_COLUMNS = list(zip(PREDICTION_COLUMNS, (pa.string(), pa.string(), pa.string(), pa.string(), pa.float64(),
                                             pa.timestamp("us"))))


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


class InferStage:
    """Predicts every image of the plan that has no prediction yet, with the run's model.

    Args:
        model: the run's model (resolved once, loaded on first use).
        on_ray: batches go to a Ray inference actor (a GPU when the cluster has one).
    """

    name = "infer"
    table = "predictions"
    owns_blobs = False
    side_tables: dict[str, pa.Schema] = {}

    def __init__(self, model: ModelHandle, on_ray: bool = False) -> None:
        self.model = model
        self.on_ray = on_ray
        self._ready: tuple[LabelMap, Callable | None] | None = None

    def schema(self, plan: Plan) -> pa.Schema:
        return predictions_schema(self._evaluator(plan))

    def key(self, job: Job) -> str:
        return job.pred_key

    def upstream(self, job: Job) -> tuple[str, str]:
        return (_table(job), job.image_key)

    def incomplete(self, plan: Plan, store: Store, cached: set[str]) -> set[str]:
        return set()

    def prepare(self, plan: Plan, store: Store) -> None:
        """Load the model and try it on one blank image, so that a broken model, a wrong output
        shape or a label it lacks fails in seconds, before anything is rendered.

        Raises:
            SpecError: naming ``model.name`` or the object's labels, with the fix.
        """
        import torch

        spec = plan.spec
        threads = spec.model.threads or os.cpu_count() or 1
        torch.set_num_threads(threads)
        try:
            model = self.model.classifier()
            labels = model.label_map()
            size = self.model.framing.crop
            logits = predict(model, np.zeros((1, size, size, 3), np.float32), self.model.name)
            _check_classes(logits, labels, self.model.name)
        except SpecError:
            raise
        except UserError as exc:
            raise SpecError(str(spec.path), "model.name", str(exc)) from None
        _truths(plan, labels)  # a label the model lacks fails now, naming the object
        runner = None
        if spec.model.backend == "onnx":
            from sweep3d.stages.infer.onnx_backend import OnnxRunner

            runner = OnnxRunner(model, store.root / "models", self.model.digest, threads)
        self._ready = (labels, runner)

    def compute(self, todo: list[Job], plan: Plan, store: Store) -> Iterator[Computed]:
        spec = plan.spec
        if self._ready is None:
            self.prepare(plan, store)
        labels, runner = self._ready
        model = self.model.classifier()
        truths = _truths(plan, labels)
        remote = None
        if self.on_ray and spec.model.backend == "torch":  # batches go to an inference actor (GPU if any)
            from sweep3d.stages.infer.ray_actor import remote_runner

            remote = remote_runner(self.model.name, self.model.framing.model)
        evaluator = self._evaluator(plan)
        schema = predictions_schema(evaluator)
        valid = {**store.column_map("renders", "valid"), **store.column_map("images", "valid")}
        digests = {t: store.digests(t) for t in ("renders", "images")}
        size = spec.model.batch_size
        for start in range(0, len(todo), size):
            t0 = time.perf_counter()
            batch, pixels, invalid, damaged = [], [], [], []
            for job in todo[start : start + size]:
                if valid.get(job.image_key) is False:  # NaN/inf upstream: not shown to the model
                    invalid.append(job)
                    continue
                image = load_image(store, job.image_key, digests[_table(job)].get(job.image_key))
                if image is None:  # damaged: discarded by the driver, recomputed by the next pass
                    damaged.append(job)
                    continue
                batch.append(job)
                pixels.append(image)
            rows = []
            if batch:
                stacked = np.stack(pixels)
                logits = remote(stacked) if remote is not None else predict(model, stacked, self.model.name, runner)
                _check_classes(logits, labels, self.model.name)
                rows = evaluator.evaluate(logits, [truths[j.object] for j in batch], labels)
            per_image = (time.perf_counter() - t0) / max(len(batch) + len(invalid), 1)
            now = utc_now()
            for job, row in [*zip(batch, rows), *((j, _invalid_row(schema)) for j in invalid)]:
                yield Computed(job.pred_key, {"pred_key": job.pred_key, "image_key": job.image_key,
                                              "model": self.model.name, "model_digest": plan.model_digest,
                                              "seconds": per_image, "created_at": now, **row})
            for job in damaged:
                yield Computed(job.pred_key, damaged=(_table(job), job.image_key))

    @staticmethod
    def _evaluator(plan: Plan) -> Evaluator:
        spec = plan.spec
        return EVALUATORS.get(spec.evaluator.kind)(top_k=spec.evaluator.top_k)


def pending_predictions(plan: Plan, store: Store) -> set[str]:
    """Prediction keys of the plan that the store lacks."""
    return {j.pred_key for j in plan.jobs} - store.keys("predictions")


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
    for i, obj in enumerate(plan.spec.objects):
        for j, label in enumerate(obj.labels):
            try:
                labels.index(label)
            except ValueError as exc:
                raise SpecError(str(plan.spec.path), f"objects[{i}].labels[{j}]",
                                f"{exc} (the classes of model {plan.spec.model.name!r})") from None
        out[obj.name] = tuple(sorted({labels.index(label) for label in obj.labels}))
    return out
