"""The postprocess stage: one image per image key, from its render and the job's post controls.

An image is valid only if its render was valid and the post controls left every pixel finite.
A render blob that is missing or damaged (its bytes do not match the digest its row recorded,
or it does not decode) is reported to the driver, which discards it so the run's next pass
renders it again. Renders arrive while the render stage goes on (see ``driver.loop``), so
their rows are read through the feed, which knows the rows of this pass before they are flushed.

Controls that declare render passes (``passes = ("depth",)``) get the job's pass arrays and its
camera as a :class:`RenderFrame`: the stage loads the blobs under the job's truth key, checked
against the digests its ``truths`` row recorded. A pass blob that is missing or damaged is
reported like a damaged render: its truth row is dropped and the run's next pass renders the
passes again (the RGB render is kept).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Iterator, Sequence

import numpy as np
import pyarrow as pa

from sweep3d.cache import (
    DIGEST_COLUMN,
    TRUTH_BLOBS,
    Store,
    atomic_write,
    load_image,
    load_pass,
    load_pixels,
    sha256_bytes,
    utc_now,
)
from sweep3d.core import BLOB_SUFFIX, TRUTH_PASSES, blamed
from sweep3d.driver import Computed, Feed, Job, JobList, Plan
from sweep3d.spec import ControlInstance, LoadedSpec
from sweep3d.stages.postprocess.apply import post_image, reads_passes
from sweep3d.stages.postprocess.frame import RenderFrame, frame_from_state
from sweep3d.stages.postprocess.handoff import ImageHandoff
from sweep3d.stages.postprocess.in_order import InOrder, worker_count
from sweep3d.stages.postprocess.post_workers import Task

IMAGES_SCHEMA = pa.schema([
    ("image_key", pa.string()), ("render_key", pa.string()), ("valid", pa.bool_()),
    ("seconds", pa.float64()), ("created_at", pa.timestamp("us")), (DIGEST_COLUMN, pa.string()),
])


def job_frame(plan: Plan, job: Job, arrays: dict[str, np.ndarray]) -> RenderFrame:
    """The job's :class:`RenderFrame`: its pass ``arrays`` and the camera its rendered controls
    pose (in their order, on a fresh ``SceneState``, as the render worker does)."""
    from sweep3d.stages.render import SceneState

    state = SceneState()
    rendered = sorted((c.control for c in plan.spec.controls if c.control.stage == "render"), key=lambda c: c.order)
    for control in rendered:
        if control.id in job.values:
            with blamed(control, "apply()"):
                control.apply(state, control.params(job.values[control.id]))
    return frame_from_state(state, plan.framing.size, plan.framing.crop, arrays.get("depth"), arrays.get("mask"))


class PostprocessStage:
    """Applies post controls to renders (a job whose image is its render has nothing to do here).

    Args:
        store_images: write each image to the store (``[postprocess] store = "all"``); without,
            its row records no digest and inference or the report make it again from its render.
        handoff: where inference takes the pixels of the images made in this process.
    """

    name = "postprocess"
    table = "images"
    side_tables: dict[str, pa.Schema] = {}

    def __init__(self, store_images: bool = True, handoff: ImageHandoff | None = None, workers: int = 1) -> None:
        self.store_images = store_images
        self.handoff = handoff
        self.workers = workers
        self.spread: InOrder | None = None  # the last pass's: which processes made its images

    @classmethod
    def for_spec(cls, spec: LoadedSpec, handoff: ImageHandoff | None = None) -> PostprocessStage:
        """The stage as ``spec``'s ``[postprocess]`` asks: ``store``, and ``workers`` (0: one per core)."""
        return cls(store_images=spec.postprocess.store == "all", handoff=handoff,
                   workers=worker_count(spec.postprocess.workers))

    @property
    def owns_blobs(self) -> bool:  # type: ignore[override]  (a run that stores no image owns no blob)
        return self.store_images

    def schema(self, plan: Plan) -> pa.Schema:
        return IMAGES_SCHEMA

    def key(self, job: Job) -> str | None:
        return job.image_key if job.image_key != job.render_key else None

    def keys_of(self, jobs: JobList) -> list[str | None]:
        return [image if image != render else None
                for render, image in zip(jobs.key_column("render_key"), jobs.key_column("image_key"))]

    def upstream(self, job: Job) -> tuple[str, str]:
        return ("renders", job.render_key)

    def incomplete(self, plan: Plan, store: Store, cached: set[str]) -> set[str]:
        return set()

    def compute(self, todo: Feed, plan: Plan, store: Store) -> Iterator[Computed]:
        post = post_controls(plan)
        render_valid = todo.column("renders", "valid")  # live: renders of this pass arrive with their jobs
        self.spread = InOrder(self._inputs(todo, plan, store, post), post, self.workers, self.store_images)
        for item in self.spread:
            if isinstance(item, Computed):
                yield item
                continue
            task, made = item
            job = task.job
            valid = render_valid.get(job.render_key) is not False and made.finite
            digest = None
            if made.png is not None:
                atomic_write(store.blob_path(job.image_key), made.png)
                digest = sha256_bytes(made.png)
            if valid and self.handoff is not None:
                self.handoff.wait_for_room()  # inference behind: no image made only to be forgotten
                self.handoff.put(job.image_key, made.pixels)
            yield Computed(job.image_key, {"image_key": job.image_key, "render_key": job.render_key, "valid": valid,
                                           "seconds": task.seconds + made.seconds, "created_at": utc_now(),
                                           DIGEST_COLUMN: digest})

    def _inputs(self, todo: Feed, plan: Plan, store: Store, post: list[ControlInstance]) -> Iterator[Computed | Task]:
        """Each job of ``todo`` with what its image is made from (its render, its passes), or why
        it cannot be made (a damaged render or pass: reported, made again by the next pass)."""
        render_digests = todo.digests("renders")
        pass_digests = truth_digests(todo)
        damaged: set[str] = set()
        seen = _SeenRenders(plan, self.handoff)
        for job in todo:
            t0 = time.perf_counter()
            pixels = None if job.render_key in damaged else seen.pixels(store, job.render_key,
                                                                        render_digests.get(job.render_key))
            if pixels is None:
                damaged.add(job.render_key)
                yield Computed(job.image_key, damaged=("renders", job.render_key))
                continue
            frame, failed = image_inputs(store, plan, job, post, pass_digests, pixels.shape[:2])
            if failed is not None:
                yield Computed(job.image_key, damaged=failed.damaged, error=failed.error)
                continue
            yield Task(job, job.render_key, pixels, job.values, job.image_key, frame, time.perf_counter() - t0)


class _SeenRenders:
    """The render the stage decoded last (a render's post-processed images come one after another
    in plan order: it is read and checked once, not once per image), handed to inference too where
    a job's image is that render itself."""

    def __init__(self, plan: Plan, handoff: ImageHandoff | None) -> None:
        self.handoff = handoff
        self.last: tuple[str, np.ndarray] | None = None
        self._as_images: set[str] | None = None
        self._plan = plan

    def pixels(self, store: Store, key: str, digests: set[str] | None) -> np.ndarray | None:
        """The render ``key``'s uint8 pixels (None: missing or damaged), read and checked once."""
        if self.last is None or self.last[0] != key:
            pixels = load_pixels(store, key, digests)
            self.last = (key, pixels) if pixels is not None else None
            if pixels is not None and self.handoff is not None and key in self.as_images():
                self.handoff.put(key, pixels)
        return self.last[1] if self.last is not None else None

    def as_images(self) -> set[str]:
        """Render keys that are also some job's image key (no post control changes that job's)."""
        if self._as_images is None:
            jobs = self._plan.jobs
            images = jobs.key_column("image_key") if isinstance(jobs, JobList) else [j.image_key for j in jobs]
            self._as_images = set(images)
        return self._as_images


@dataclass(frozen=True)
class Made:
    """One post-processed image as the store keeps it, or why it could not be made.

    Attributes:
        pixels: uint8 (H, W, 3), what a stored PNG holds (None: not made).
        finite: the float image had no NaN or inf before it was quantised.
        damaged: (table, key) of an input blob missing or damaged (its row goes; made again).
        error: why the job cannot be post-processed at all.
    """

    pixels: np.ndarray | None
    finite: bool = False
    damaged: tuple[str, str] | None = None
    error: str | None = None


def post_controls(plan: Plan) -> list[ControlInstance]:
    """The plan's post controls, in spec order."""
    return [c for c in plan.spec.controls if c.control.stage == "post"]


def truth_digests(source: Feed | Store) -> dict[str, Any]:
    """Pass name → (truth key → the digests its truth rows recorded), live where ``source`` is a feed."""
    return {name: source.digests("truths", TRUTH_BLOBS[BLOB_SUFFIX[name]]) for name in TRUTH_PASSES}


def make_image(store: Store, plan: Plan, job: Job, post: Sequence[ControlInstance], render_digests: set[str] | None,
               pass_digests: dict[str, Any]) -> Made:
    """The job's post-processed image from its stored render (and passes, for the controls that
    read them), as the stage makes it: what inference and the report make again for an image that
    was not stored."""
    render = load_image(store, job.render_key, render_digests)
    if render is None:
        return Made(None, damaged=("renders", job.render_key))
    frame, failed = image_inputs(store, plan, job, post, pass_digests, render.shape[:2])
    if failed is not None:
        return failed
    return Made(*post_image(render, post, job.values, job.image_key, frame))


def image_inputs(store: Store, plan: Plan, job: Job, post: Sequence[ControlInstance], pass_digests: dict[str, Any],
                 shape: tuple[int, ...]) -> tuple[RenderFrame | None, Made | None]:
    """(the frame the job's post controls read, None when none reads a pass; or, second, a
    :class:`Made` saying why its image cannot be made: a pass missing or damaged)."""
    wanted = sorted({p for inst in post for p in reads_passes(inst, job.values)})
    if not wanted:
        return None, None
    if job.truth_key is None:
        return None, Made(None, error="a post control reads render passes the plan did not ask for")
    arrays = {name: _pass(store, job, name, pass_digests[name], shape) for name in wanted}
    if any(a is None for a in arrays.values()):  # its truth row goes: the passes are rendered again
        return None, Made(None, damaged=("truths", job.truth_key))
    return job_frame(plan, job, arrays), None


def _pass(store: Store, job: Job, name: str, digests: Any, shape: tuple[int, ...]) -> np.ndarray | None:
    """One pass of the job's render, checked against the digests its truth rows recorded (and
    against the image's size); None when it is missing, damaged or of another size."""
    assert job.truth_key is not None
    array = load_pass(store, job.truth_key, name, digests.get(job.truth_key))
    return array if array is not None and array.shape == tuple(shape) else None
