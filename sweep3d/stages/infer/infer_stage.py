"""The infer stage: batched forward passes over every image whose prediction is not cached.

Which backend computes the predictions is ``prediction_keys.choose_backend``'s choice: by default
ONNX Runtime standing in for torch, whose ranks are torch's (``onnx_backend``); torch computing
for the same model is named in the prediction keys (``prediction_keys.key_backend``), since the
probabilities of the two differ in the last digits. A stand-in that cannot serve refuses the run
rather than handing its keys to torch.

An image's outputs are the same bits whatever batch it lands in (images are batched as they
arrive, so which images share a batch changes run to run): torch's kernels sum in another order
for another batch size, so batches that torch computes are padded to ``batch_size``; ONNX
Runtime's rows on the CPU are the same bits at any batch size, position, company or thread count
(benchmarks/RESULTS.md), so its batches are not.

A prediction is valid only if its image was valid (no NaN/inf in the render or after post
controls) and the model's outputs are finite; an invalid image is not shown to the model and
gets a row with ``valid = false``, so it is counted as invalid and never averaged. An image blob
that is missing or damaged is discarded so the next pass of the run computes it again.
"""

from __future__ import annotations

import itertools
import logging
import os
import time
from typing import TYPE_CHECKING, Any, Callable, Iterable, Iterator, Mapping

import numpy as np
import pyarrow as pa

from sweep3d.cache import Store, load_pass, load_pixels, utc_now
from sweep3d.core import SpecError, UserError, from_uint8
from sweep3d.driver import Computed, Feed, Job, JobList, Plan, unique_jobs
from sweep3d.spec import PREDICTION_COLUMNS
from sweep3d.stages.infer.evaluate import evaluate_checked
from sweep3d.stages.infer.evaluators import EVALUATORS, Evaluator, Truth
from sweep3d.stages.infer.handle import ModelHandle, model_key_path
from sweep3d.stages.infer.kept_outputs import KeptOutputs
from sweep3d.stages.infer.labels import LabelMap
from sweep3d.stages.infer.models import Classifier, builtin_model
from sweep3d.stages.infer.outputs import Localized
from sweep3d.stages.infer.prediction_keys import STAND_IN, choose_backend
from sweep3d.stages.infer.task_calls import check_task, model_outputs
from sweep3d.stages.infer.torch_aside import MIN_IMAGES as ASIDE_MIN_IMAGES
from sweep3d.stages.postprocess import ImageHandoff, make_image, post_controls, truth_digests

if TYPE_CHECKING:
    from sweep3d.stages.infer.onnx_backend import OnnxRunner

log = logging.getLogger("sweep3d.infer")

#: The bookkeeping columns of every prediction row (named in ``spec.columns``, which reserves them).
BASE_COLUMNS = list(zip(PREDICTION_COLUMNS, (pa.string(), pa.string(), pa.string(), pa.string(), pa.float64(),
                                             pa.timestamp("us"))))


def predictions_schema(evaluator: Evaluator) -> pa.Schema:
    return pa.schema(BASE_COLUMNS + list(zip(evaluator.schema.names, evaluator.schema.types)))


class InferStage:
    """Predicts every image of the plan that has no prediction yet, with the run's model.

    Images arrive while the stages upstream go on (see ``driver.loop``); a batch is inferred
    once ``batch_size`` images are there, or the last ones are.

    Args:
        model: the run's model (resolved once, loaded on first use).
        on_ray: batches that torch computes go to a Ray inference actor (a GPU when the cluster has
            one); ONNX Runtime, standing in or asked for, infers here as in a local run, so the
            bytes under a key are the same whichever executor made the renders.
        several: the run infers several models (each progress bar names its model).
        handoff: the post-processed images made in this process (taken before any blob is read).
        images_stored: post-processed images are written to the store (``[postprocess] store``).
    """

    name = "infer"
    table = "predictions"
    owns_blobs = False
    side_tables: dict[str, pa.Schema] = {}

    def __init__(self, model: ModelHandle, on_ray: bool = False, several: bool = False,
                 handoff: ImageHandoff | None = None, images_stored: bool = True) -> None:
        self.model = model
        self.on_ray = on_ray
        self.handoff = handoff
        #: the tables whose blobs must exist before a job is inferred (see ``driver.split_to_do``):
        #: an image that is not stored is made again from its render.
        self.blob_inputs = ("renders", "images") if images_stored else ("renders",)
        self.title = f"infer {model.label}" if several else self.name  # its progress bar
        self.backend: str | None = None  # chosen by ``prepare``
        self._labels: LabelMap | None = None
        self._runner: OnnxRunner | None = None
        self._model: Classifier | None = None  # what prepare tried: the loaded model, or a built-in's unloaded view
        self._made: tuple[Any, Evaluator] | None = None  # (the spec's [evaluator], the evaluator it made)

    def schema(self, plan: Plan) -> pa.Schema:
        return predictions_schema(self._evaluator(plan))

    def required_columns(self, plan: Plan) -> tuple[list[str], str]:
        """The columns every prediction of the run's evaluator has, and whose they are: a stored
        segment of its keys without one was rewritten without it (see ``Store.require_columns``),
        and its rows would read as NULLs."""
        return self.schema(plan).names, f"every row of the {plan.spec.evaluator.kind} evaluator has"

    def key(self, job: Job) -> str:
        return job.pred_key

    def keys_of(self, jobs: JobList) -> list[str | None]:
        return jobs.key_column("pred_key")

    def upstream(self, job: Job) -> tuple[str, str]:
        return (_table(job), job.image_key)

    def incomplete(self, plan: Plan, store: Store, cached: set[str]) -> set[str]:
        return set()

    def prepare(self, plan: Plan, store: Store) -> None:
        """Load the model and try it on one blank image, so that a broken model, a wrong output
        shape or a label it lacks fails in seconds, before anything is rendered. A built-in model
        that ONNX Runtime serves is tried through ONNX Runtime, and torch is not imported unless
        its graph must be exported or checked (see ``onnx_kept``).

        Raises:
            SpecError: naming ``model.name`` or the object's labels, with the fix.
        """
        spec = plan.spec
        task = self._evaluator(plan).task
        self.backend = choose_backend(spec, self.model.settings)
        if self.backend == "onnx" and task != "classification":
            raise SpecError(str(spec.path), model_key_path(spec, self.model.settings).replace("name", "backend"),
                            f"the onnx backend serves classification only, not {task!r}; use backend = \"torch\"")
        served = self.backend in ("onnx", STAND_IN) and builtin_model(self.model.name) is not None
        if served:
            self._model = self.model.unloaded()
            object_class_ids(plan, self._model.label_map(), self.model.name)
            self._runner = self._runner or self._served_by_onnx(plan, store)
        if not served:
            import torch

            torch.set_num_threads(self._threads())
            self._model = self.model.classifier()
        model = self._model
        try:
            labels = model.label_map()
            check_task(model, task, self.model.name)
            size = self.model.framing.crop
            outputs = model_outputs(model, np.zeros((1, size, size, 3), np.uint8), task, self.model.name,
                                    self._runner.unranked if served else None)  # shapes and classes: no torch
            _check_classes(outputs, labels, self.model.name)
        except SpecError:
            raise
        except UserError as exc:
            raise SpecError(str(spec.path), model_key_path(spec, self.model.settings), str(exc)) from None
        object_class_ids(plan, labels, self.model.name)  # a label the model lacks fails now, naming the object
        if self.backend in ("onnx", STAND_IN) and self._runner is None:
            self._runner = self._served_by_onnx(plan, store)
        if self.backend == STAND_IN and self._runner is not None and len(plan.jobs) >= ASIDE_MIN_IMAGES \
                and (os.cpu_count() or 1) > 1:  # prepare runs on the thread that outlives the pass
            self._runner.answer_ties_aside(self.model.name)
        self._labels = labels

    def close(self) -> None:
        """End what the stage keeps beside the run (the process answering near ties)."""
        if self._runner is not None:
            self._runner.close()

    def _served_by_onnx(self, plan: Plan, store: Store) -> OnnxRunner:
        """The ONNX Runtime runner of the run's backend, asked for or standing in (exported and
        checked now, before anything renders); its failure is the user's to see now."""
        if self.backend == "onnx":
            return self._onnx(plan, store, self._threads())
        return self._stand_in(plan, store, self._threads(beside=True))

    def compute(self, todo: Feed, plan: Plan, store: Store) -> Iterator[Computed]:
        if self._labels is None:
            self.prepare(plan, store)
        valid = {t: todo.column(t, "valid") for t in ("renders", "images")}  # live: see Feed
        images = ModelInputs(store, plan, todo, self.handoff)
        jobs = iter(todo)
        first = next(jobs, None)
        if first is None:
            return  # nothing came (its inputs failed): nothing to load
        kept = KeptOutputs(store, plan.model_digest, self._answers(plan), self._evaluator(plan).task)
        try:
            yield from self._predicted(plan, store, todo, images, valid, itertools.chain([first], jobs), kept)
        finally:
            kept.close()

    def _predicted(self, plan: Plan, store: Store, todo: Feed, images: ModelInputs, valid: dict[str, Mapping[str, Any]],
                 jobs: Iterable[Job], kept: KeptOutputs) -> Iterator[Computed]:
        """The prediction rows of ``jobs``, batch by batch."""
        threads = self._threads(beside="render" in todo.computing)
        infer = self._inferrer(plan, store, threads, kept)
        widen = threads < self._threads() and self._widens()
        passes = self._evaluator(plan).passes
        for batch_jobs in _batches(jobs, self.model.settings.batch_size):
            if widen and (not todo.more or "render" in todo.finished):  # the renders are done: every core
                self._runner.use_threads(self._threads())  # type: ignore[union-attr]
                widen = False
            t0 = time.perf_counter()
            batch, pixels, invalid, damaged = _load(images, batch_jobs, valid)
            arrays, lost = _load_passes(store, batch, passes)
            if lost:
                keep = [i for i, job in enumerate(batch) if job not in lost]
                batch, pixels, arrays = [batch[i] for i in keep], [pixels[i] for i in keep], [arrays[i] for i in keep]
            rows = infer(batch, pixels, arrays) if batch else []
            per_image = (time.perf_counter() - t0) / max(len(batch) + len(invalid), 1)
            yield from self._computed(plan, batch, rows, invalid, per_image)
            for job, source in damaged:
                yield Computed(job.pred_key, damaged=source)
            for job in lost:  # its truth row goes, so the render stage renders its passes again
                yield Computed(job.pred_key, damaged=("truths", job.truth_key))

    def _inferrer(self, plan: Plan, store: Store, threads: int,
                  kept: KeptOutputs) -> Callable[[list[Job], list[np.ndarray], list[dict]], list[dict]]:
        """A function from a batch's jobs and pixels to their evaluator rows, on the run's backend
        with ``threads`` threads (the model's outputs read from and kept in ``kept``)."""
        labels = self._labels
        truths = object_class_ids(plan, labels, self.model.name)
        evaluator, kind = self._evaluator(plan), plan.spec.evaluator.kind
        if self.backend == STAND_IN and self._runner is None:
            self._runner = self._stand_in(plan, store, threads)
        if self._runner is not None:  # torch, if ever loaded, runs the odd near tie on one thread (onnx_backend)
            self._runner.use_threads(threads)
            model = self._model if self._model is not None else self.model.classifier()
        else:
            import torch

            model = self.model.classifier()
            torch.set_num_threads(threads)
        remote = None
        if self.on_ray and self.backend == "torch" and evaluator.task == "classification":  # batches go to an inference actor (GPU if any)
            from sweep3d.stages.infer.ray_actor import remote_runner

            remote = remote_runner(self.model.name, self.model.framing.model)

        def infer(jobs: list[Job], pixels: list[np.ndarray], arrays: list[dict]) -> list[dict]:
            images = [j.image_key for j in jobs]
            outputs = kept.load(images)  # kept from an earlier evaluator of the same model
            computed = outputs is None
            if computed:
                stacked = padded(np.stack(pixels), self.model.settings.batch_size if self._pads() else 0)
                if remote is not None:
                    outputs = remote(from_uint8(stacked))
                else:
                    outputs = model_outputs(model, stacked, evaluator.task, self.model.name, self._runner)
                outputs = first_rows(outputs, len(pixels))
            _check_classes(outputs, labels, self.model.name)
            if computed:
                kept.save(images, outputs)
            return evaluate_checked(evaluator, kind, outputs,
                                    [Truth(truths[j.object], **a) for j, a in zip(jobs, arrays)], labels)

        return infer

    def _computed(self, plan: Plan, batch: list[Job], rows: list[dict], invalid: list[Job],
                  per_image: float) -> Iterator[Computed]:
        """The prediction rows of a batch: evaluated images, then those with invalid pixels."""
        schema = predictions_schema(self._evaluator(plan))
        now = utc_now()
        for job, row in [*zip(batch, rows), *((j, _invalid_row(schema)) for j in invalid)]:
            yield Computed(job.pred_key, {"pred_key": job.pred_key, "image_key": job.image_key,
                                          "model": self.model.label, "model_digest": plan.model_digest,
                                          "seconds": per_image, "created_at": now, **row})

    def _onnx(self, plan: Plan, store: Store, threads: int, exact_ranks: int | None = None) -> OnnxRunner:
        from sweep3d.stages.infer.onnx_backend import OnnxRunner

        return OnnxRunner(self.model.classifier, store.root / "models", self.model.digest, threads,
                          exact_ranks, scratch=store.root / "tmp")

    def _stand_in(self, plan: Plan, store: Store, threads: int) -> OnnxRunner:
        """ONNX Runtime standing in for torch.

        Raises:
            UserError: it cannot (a full disk, an export that fails or disagrees with torch). Torch
                inferring instead would store its rows under the stand-in's keys, whose rows
                elsewhere (another run, another store) are ONNX Runtime's: the same ranks, other
                last digits. ``backend = "torch"`` has keys of its own.
        """
        try:
            top_k = getattr(self._evaluator(plan).params, "top_k", 5)
            return self._onnx(plan, store, threads, exact_ranks=max(top_k, 5))  # and top-5
        except Exception as exc:  # noqa: BLE001  (whatever stops ONNX Runtime: one line, the run stops)
            where = model_key_path(plan.spec, self.model.settings).replace("name", "backend")
            reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0].split(";")[0]
            raise UserError(f"ONNX Runtime cannot stand in for torch for {self.model.name} ({reason}); fix that "
                            f"and run again, or set {where} = \"torch\" to infer with torch (its predictions are "
                            "keyed apart: their probabilities differ from ONNX Runtime's in the last digits)") from None

    def _answers(self, plan: Plan) -> str:
        """Whose answers the outputs are, for keeping them: the backend, and for ONNX Runtime standing
        in for torch the ranks it checked against torch (another ``top_k`` needs others checked)."""
        if self.backend == STAND_IN:
            return f"{STAND_IN}:{max(getattr(self._evaluator(plan).params, 'top_k', 5), 5)}"
        return self.backend or "torch"

    def _pads(self) -> bool:
        """Whether batches are padded to ``batch_size``: where torch computes them (its answers
        change with the batch size), not where ONNX Runtime does on the CPU (they do not)."""
        return self._runner is None or not self._runner.batch_invariant

    def _threads(self, beside: bool = False) -> int:
        """Inference threads: the model's setting, else one ``beside`` renders of the pass
        (Blender renders on every core: one thread gave the shortest runs, benchmarks/RESULTS.md),
        else every core (beside post-processing alone, which takes one core for a fraction of
        the time, every core took the quickstart's 960 images from 13–15 s to 8–10 s: issue 37). Chosen from what the pass had to do, not
        from how fast upstream went, since torch's answers change with its thread count; only
        where they cannot change does inference widen once upstream is done (:meth:`_widens`)."""
        return self.model.settings.threads or (1 if beside else os.cpu_count() or 1)

    def _widens(self) -> bool:
        """Whether the pass's last batches may take every core once the stages upstream are done:
        where ONNX Runtime stands in for a built-in classifier on the CPU, whose rows are the same
        bits at any thread count (``test_onnx_rows_are_the_same_bits_at_any_thread_count``), so
        that how fast the renders went changes nothing stored."""
        return self.backend == STAND_IN and self._runner is not None and self._runner.batch_invariant

    def _evaluator(self, plan: Plan) -> Evaluator:
        """The run's evaluator, made once (the schema and the rows of every batch come from it)."""
        settings = plan.spec.evaluator
        if self._made is None or self._made[0] is not settings:
            self._made = (settings, EVALUATORS.get(settings.kind).from_settings(settings))
        return self._made[1]


def pending_predictions(plan: Plan, store: Store, stage: InferStage | None = None) -> bool:
    """Whether the store lacks any prediction key of the plan.

    Args:
        stage: the run's infer stage, whose distinct keys the plan then remembers for its pass.
    """
    keys = unique_jobs(stage, plan.jobs) if stage is not None else {j.pred_key for j in plan.jobs}
    return not store.key_set("predictions").issuperset(keys)


def _load(images: ModelInputs, jobs: list[Job], valid: dict[str, Mapping[str, Any]]
          ) -> tuple[list[Job], list[np.ndarray], list[Job], list[tuple[Job, tuple[str, str]]]]:
    """A batch's pixels: (jobs with a good image, their pixels, jobs whose image has NaN/inf
    upstream and is not shown to the model, jobs whose input blob is damaged or missing with
    that blob's (table, key))."""
    batch, pixels, invalid, damaged = [], [], [], []
    for job in jobs:
        if valid[_table(job)].get(job.image_key) is False:
            invalid.append(job)
            continue
        image = images.pixels(job)
        if isinstance(image, tuple):  # discarded by the driver, recomputed by the run's next pass
            damaged.append((job, image))
            continue
        batch.append(job)
        pixels.append(image)
    return batch, pixels, invalid, damaged


class ModelInputs:
    """Where each job's image comes from: the postprocess stage's handoff (made in this process),
    else its stored blob, else made again from its render (an image that was not stored)."""

    def __init__(self, store: Store, plan: Plan, todo: Feed, handoff: ImageHandoff | None) -> None:
        self.store, self.plan, self.handoff = store, plan, handoff
        self.digests = {t: todo.digests(t) for t in ("renders", "images")}  # live: see Feed
        self.passes = truth_digests(todo)
        self.post = post_controls(plan)

    def pixels(self, job: Job) -> np.ndarray | tuple[str, str]:
        """uint8 (H, W, 3), what the stored PNG holds (the model's preprocessing makes them float,
        or looks them up: ``models.preprocessed``), or the (table, key) of the input found damaged
        or missing."""
        table = _table(job)
        kept = self.handoff.take(job.image_key) if self.handoff is not None else None
        if kept is not None:  # made (or decoded, for a render) by the postprocess stage in this process
            return kept
        if table == "images":
            recorded = self.digests["images"].get(job.image_key)
            if not recorded:  # not stored: made again (a blob the report wrote, unrecorded, is a copy)
                made = make_image(self.store, self.plan, job, self.post,
                                  self.digests["renders"].get(job.render_key), self.passes)
                if made.pixels is None:
                    return made.damaged or ("images", job.image_key)
                return made.pixels
        image = load_pixels(self.store, job.image_key, self.digests[table].get(job.image_key))
        return (table, job.image_key) if image is None else image


def _batches(jobs: Iterable[Job], size: int) -> Iterator[list[Job]]:
    """``jobs`` in lists of ``size`` (the last may be shorter), each as soon as it is full."""
    batch: list[Job] = []
    for job in jobs:
        batch.append(job)
        if len(batch) == size:
            yield batch
            batch = []
    if batch:
        yield batch


def padded(images: np.ndarray, size: int) -> np.ndarray:
    """``images`` with copies of the last one appended up to ``size`` images: at one batch shape,
    torch gives an image the same bits whatever its position and the other images (checked on
    EfficientNet-Lite0), so its outputs no longer depend on the batch it landed in."""
    if len(images) >= size:
        return images
    return np.concatenate([images, np.repeat(images[-1:], size - len(images), axis=0)])


def first_rows(outputs: Any, n: int) -> Any:
    """The first ``n`` images' outputs of a batch's (logits, a raw array, detections, score
    maps or a :class:`Localized`): the images before :func:`padded`'s copies."""
    if isinstance(outputs, Localized):
        return Localized(outputs.logits[:n], outputs.boxes[:n])
    return outputs[:n]


def _table(job: Job) -> str:
    """The table whose row describes the image this job's model sees."""
    return "renders" if job.image_key == job.render_key else "images"


def _invalid_row(schema: pa.Schema) -> dict:
    """Evaluator columns for an image with NaN/inf pixels: valid = false, everything else null."""
    row = {name: None for name in schema.names if name not in dict(BASE_COLUMNS)}
    if "valid" in row:
        row["valid"] = False
    return row


def _load_passes(store: Store, jobs: list[Job], passes: tuple[str, ...]) -> tuple[list[dict], set[Job]]:
    """Each job's pass arrays for the evaluator (``{"mask": ..., "depth": ...}``), and the jobs
    whose pass blobs are missing or undecodable."""
    if not passes:
        return [{} for _ in jobs], set()
    arrays, lost = [], set()
    for job in jobs:
        found = {name: load_pass(store, job.truth_key, name) if job.truth_key else None for name in passes}
        if any(v is None for v in found.values()):
            lost.add(job)
        arrays.append(found)
    return arrays, lost


def _check_classes(outputs: Any, labels: LabelMap, name: str) -> None:
    """A classifier's or localizer's logits must have one column per class of its label map."""
    logits = getattr(outputs, "logits", outputs)
    if not isinstance(logits, np.ndarray) or logits.ndim != 2:
        return  # detections and scores are checked against the label map as they are read
    if logits.shape[1] != len(labels):
        raise UserError(f"model {name!r} returns {logits.shape[1]} classes but its label map has {len(labels)}; "
                        "return one logit per class, or give the Classifier its own labels")


def object_class_ids(plan: Plan, labels, model: str) -> dict[str, tuple[int, ...]]:
    """Ground-truth class ids per object, in the model's label space."""
    out = {}
    for i, obj in enumerate(plan.spec.objects):
        for j, label in enumerate(obj.labels):
            try:
                labels.index(label)
            except ValueError as exc:
                raise SpecError(str(plan.spec.path), f"objects[{i}].labels[{j}]",
                                f"{exc} (the classes of model {model!r})") from None
        out[obj.name] = tuple(sorted({labels.index(label) for label in obj.labels}))
    return out
