"""The postprocess stage: one image per image key, from its render and the job's post controls.

An image is valid only if its render was valid and the post controls left every pixel finite.
A render blob that is missing or damaged (its bytes do not match the digest its row recorded,
or it does not decode) is discarded so the next pass of the run renders it again.
"""

from __future__ import annotations

import time
from typing import Any, Sequence

import numpy as np
import pyarrow as pa

from sweep3d.cache.blobs import load_image, sha256_bytes
from sweep3d.cache.store import DIGEST_COLUMN, Store, atomic_write, utc_now
from sweep3d.pixels import encode_png
from sweep3d.progress import RunProgress
from sweep3d.spec.loader import ControlInstance
from sweep3d.stages.outcome import StageOutcome
from sweep3d.stages.plan.jobs import Job, Plan

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
            out = inst.control.apply(out, inst.control.params(values[inst.id]), rng)
    return np.asarray(out, dtype=np.float32)


def postprocess_stage(plan: Plan, store: Store, progress: RunProgress) -> StageOutcome:
    started = time.perf_counter()
    post = [c for c in plan.spec.controls if c.control.stage == "post"]
    unique: dict[str, Job] = {}
    for job in plan.jobs:
        if job.image_key != job.render_key:
            unique.setdefault(job.image_key, job)
    have = store.keys("images")
    cached = {k for k in unique if k in have and store.blob_path(k).exists()}
    store.drop_rows("images", {k for k in unique if k in have and k not in cached})  # blob gone: redo
    renders = store.keys("renders")
    todo = [j for k, j in unique.items() if k not in cached and j.render_key in renders
            and store.blob_path(j.render_key).exists()]
    outcome = StageOutcome("postprocess", total=len(unique), cached=len(cached),
                           skipped=len(unique) - len(cached) - len(todo))
    if todo:
        render_valid = store.column_map("renders", "valid")
        render_digests = store.digests("renders")
        damaged: set[str] = set()
        with progress.stage("postprocess", len(todo), len(cached)) as bar, \
                store.segment_writer("images", IMAGES_SCHEMA) as writer:
            for job in todo:
                t0 = time.perf_counter()
                render = None if job.render_key in damaged else \
                    load_image(store, job.render_key, render_digests.get(job.render_key))
                if render is None:  # damaged render: discarded below, rendered again next pass
                    damaged.add(job.render_key)
                    outcome.skipped += 1
                    bar.advance()
                    continue
                image = apply_post(render, post, job.values, job.image_key)
                valid = render_valid.get(job.render_key) is not False and bool(np.isfinite(image).all())
                data = encode_png(image)
                atomic_write(store.blob_path(job.image_key), data)
                writer.add({"image_key": job.image_key, "render_key": job.render_key, "valid": valid,
                            "seconds": time.perf_counter() - t0, "created_at": utc_now(),
                            DIGEST_COLUMN: sha256_bytes(data)})
                outcome.computed += 1
                bar.advance()
        store.discard("renders", damaged, "are damaged (digest mismatch or undecodable)")
    outcome.seconds = time.perf_counter() - started
    return outcome
