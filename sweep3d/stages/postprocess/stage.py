"""The postprocess stage: one image per image key, from its render and the job's post controls.

An image is valid only if its render was valid and the post controls left every pixel finite.
A render blob that is missing or damaged (its bytes do not match the digest its row recorded,
or it does not decode) is reported to the driver, which discards it so the run's next pass
renders it again. Renders arrive while the render stage goes on (see ``stages.driver``), so
their rows are read through the feed, which knows the rows of this pass before they are flushed.
"""

from __future__ import annotations

import time
from typing import Any, Iterator, Sequence

import numpy as np
import pyarrow as pa

from sweep3d.cache.blobs import load_image, sha256_bytes
from sweep3d.cache.store import DIGEST_COLUMN, Store, atomic_write, utc_now
from sweep3d.controls import blamed
from sweep3d.errors import PluginError
from sweep3d.pixels import encode_png
from sweep3d.spec.loader import ControlInstance
from sweep3d.stages.driver import Computed, Feed
from sweep3d.stages.jobs import Job, Plan

IMAGES_SCHEMA = pa.schema([
    ("image_key", pa.string()), ("render_key", pa.string()), ("valid", pa.bool_()),
    ("seconds", pa.float64()), ("created_at", pa.timestamp("us")), (DIGEST_COLUMN, pa.string()),
])


def apply_post(image: np.ndarray, controls: Sequence[ControlInstance], values: dict[str, dict[str, Any]],
               seed_key: str) -> np.ndarray:
    """Apply the post controls that this job has, in spec order.

    Args:
        image: float32 (H, W, 3) in [0, 1].
        seed_key: the job's image key; seeds the random generator so results are reproducible.
    """
    rng = np.random.default_rng(int(seed_key[:16], 16))
    out = image
    for inst in controls:
        if inst.id in values and not inst.control.is_identity(values[inst.id]):
            out = _applied(inst, out, inst.control.params(values[inst.id]), rng)
    return np.asarray(out, dtype=np.float32)


def _applied(inst: ControlInstance, image: np.ndarray, params: Any, rng: np.random.Generator) -> np.ndarray:
    """One control's ``apply``; a user's control that raises or returns no image of ``image``'s
    shape is a :class:`PluginError` naming it (sweep3d's own controls' failures are bugs: raised)."""
    control = inst.control
    with blamed(control, "failed in apply()"):
        out = control.apply(image, params, rng)
    try:
        array = np.asarray(out, dtype=np.float32)
    except (TypeError, ValueError):
        array = None
    if array is None or array.shape != image.shape:
        what = f"an array of shape {array.shape}" if array is not None else f"a {type(out).__name__}"
        raise PluginError(f"control {control.type_name!r} (id {inst.id!r}) returned {what} from apply(); return the image as a float array of shape "
                          f"{image.shape} (H, W, 3), values in [0, 1]")
    return array


class PostprocessStage:
    """Applies post controls to renders (a job whose image is its render has nothing to do here)."""

    name = "postprocess"
    table = "images"
    owns_blobs = True
    side_tables: dict[str, pa.Schema] = {}

    def schema(self, plan: Plan) -> pa.Schema:
        return IMAGES_SCHEMA

    def key(self, job: Job) -> str | None:
        return job.image_key if job.image_key != job.render_key else None

    def upstream(self, job: Job) -> tuple[str, str]:
        return ("renders", job.render_key)

    def incomplete(self, plan: Plan, store: Store, cached: set[str]) -> set[str]:
        return set()

    def compute(self, todo: Feed, plan: Plan, store: Store) -> Iterator[Computed]:
        post = [c for c in plan.spec.controls if c.control.stage == "post"]
        render_valid = todo.column("renders", "valid")  # live: renders of this pass arrive with their jobs
        render_digests = todo.digests("renders")
        damaged: set[str] = set()
        for job in todo:
            t0 = time.perf_counter()
            render = None if job.render_key in damaged else \
                load_image(store, job.render_key, render_digests.get(job.render_key))
            if render is None:
                damaged.add(job.render_key)
                yield Computed(job.image_key, damaged=("renders", job.render_key))
                continue
            image = apply_post(render, post, job.values, job.image_key)
            valid = render_valid.get(job.render_key) is not False and bool(np.isfinite(image).all())
            data = encode_png(image)
            atomic_write(store.blob_path(job.image_key), data)
            yield Computed(job.image_key, {"image_key": job.image_key, "render_key": job.render_key, "valid": valid,
                                           "seconds": time.perf_counter() - t0, "created_at": utc_now(),
                                           DIGEST_COLUMN: sha256_bytes(data)})
