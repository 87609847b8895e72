"""The render stage: every render key the plan needs and the store lacks, grouped by scene.

A render counts as stored when it has a row and a blob; a row whose blob has gone is dropped
and the key rendered again. Each row records the SHA-256 of its blob, so readers can tell a
damaged blob from a good one. A job that fails because of the user's input (a mesh or HDRI
Blender cannot use, a full disk) stops the run with a one-line error naming the spec key.

When the report asks for part visibility, workers also write a UV pass and each render records
which parts of the object it shows (the ``parts`` table, one row per ``parts_key``). A render
that is cached but lacks that row is rendered again for the pass only: its blob is kept.
"""

from __future__ import annotations

import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa

from sweep3d.cache.blobs import sha256_bytes
from sweep3d.cache.store import DIGEST_COLUMN, Store, utc_now
from sweep3d.errors import SpecError, UserError
from sweep3d.parts import PARTS_LAYOUT
from sweep3d.progress import RunProgress
from sweep3d.stages.outcome import StageOutcome
from sweep3d.stages.plan.jobs import Job, Plan
from sweep3d.stages.render.assets import materialise_mesh
from sweep3d.stages.render.pool import RenderPool
from sweep3d.stages.render.protocol import (
    EnvironmentRef,
    RenderExecutor,
    RenderInfo,
    RenderJob,
    RenderReply,
    RenderSettings,
)

GROUP_SIZE = 32  # jobs sent to a worker at once; a scene's jobs stay together in order

RENDERS_SCHEMA = pa.schema([
    ("render_key", pa.string()), ("width", pa.int32()), ("height", pa.int32()), ("valid", pa.bool_()),
    ("seconds", pa.float64()), ("created_at", pa.timestamp("us")), (DIGEST_COLUMN, pa.string()),
])
PARTS_SCHEMA = pa.schema([
    ("parts_key", pa.string()), ("render_key", pa.string()), ("layout", pa.string()),
    ("parts", pa.list_(pa.int16())), ("pixels", pa.list_(pa.int32())), ("object_pixels", pa.int32()),
    ("created_at", pa.timestamp("us")),
])


def cached_renders(plan: Plan, store: Store) -> set[str]:
    """Render keys of the plan that have a complete row and a blob in the store."""
    have = store.keys("renders")
    return {j.render_key for j in plan.jobs if j.render_key in have and store.blob_path(j.render_key).exists()}


def renders_to_do(plan: Plan, store: Store, cached: set[str] | None = None) -> list[Job]:
    """One job per render key the store lacks, or whose UV-pass parts it lacks when asked for."""
    cached = cached_renders(plan, store) if cached is None else cached
    have_parts = store.keys("parts") if plan.spec.spec.report.part_visibility else set()
    unique: dict[str, Job] = {}
    for job in plan.jobs:
        unique.setdefault(job.render_key, job)
    return [job for key, job in unique.items()
            if key not in cached or (job.parts_key is not None and job.parts_key not in have_parts)]


def _stale_rows(plan: Plan, store: Store, cached: set[str]) -> set[str]:
    """Render keys of the plan with a row but no blob (deleted, or moved to quarantine)."""
    have = store.keys("renders")
    return {j.render_key for j in plan.jobs if j.render_key in have and j.render_key not in cached}


@dataclass(frozen=True)
class Executor:
    """Where renders run: ``local`` worker processes (the default) or a ``ray`` cluster
    (``address`` of an existing cluster, or None for a local one on loopback)."""

    kind: str = "local"
    address: str | None = None

    def pool(self, settings: RenderSettings, workers: int, timeout: float) -> RenderExecutor:
        """A fresh executor of this kind (``timeout`` applies to local workers only)."""
        if self.kind == "ray":
            from sweep3d.stages.render.ray_pool import RayRenderPool

            return RayRenderPool(settings, workers, self.address)
        return RenderPool(settings, workers, timeout)


LOCAL = Executor()


def render_stage(plan: Plan, store: Store, progress: RunProgress, executor: Executor = LOCAL) -> StageOutcome:
    """Render what is missing; rows are flushed every few seconds so a kill loses little."""
    started = time.perf_counter()
    unique: dict[str, Job] = {}
    for job in plan.jobs:
        unique.setdefault(job.render_key, job)
    cached = cached_renders(plan, store)
    store.drop_rows("renders", _stale_rows(plan, store, cached))  # rendered again below, one row each
    todo = renders_to_do(plan, store, cached)
    outcome = StageOutcome("render", total=len(unique), cached=len(unique) - len(todo))
    if todo:
        groups = _groups(plan, store, todo, cached)
        settings = plan.render_settings()
        workers = min(plan.spec.spec.render.workers, len(groups))
        with progress.stage("render", len(todo), outcome.cached) as bar, \
                executor.pool(settings, workers, plan.spec.spec.render.timeout) as pool, \
                store.segment_writer("renders", RENDERS_SCHEMA) as writer, \
                store.segment_writer("parts", PARTS_SCHEMA) as parts_writer:
            for reply in pool.run(groups):
                job = unique[reply.render_key]
                if not reply.ok and reply.kind == "user":
                    raise _user_error(plan, job, reply.error or "")
                ok = reply.ok and (job.render_key in cached or _record_render(store, writer, reply))
                if ok and job.parts_key is not None:
                    _record_parts(parts_writer, job, reply.info)
                if ok:
                    outcome.computed += 1
                else:
                    outcome.failed += 1
                    error = reply.error or "the worker reported success but its blob cannot be read"
                    outcome.errors.append(f"render {reply.render_key[:12]}: {error}")
                bar.advance(failed=not ok)
    outcome.seconds = time.perf_counter() - started
    return outcome


def _record_render(store: Store, writer, reply: RenderReply) -> bool:
    """Add a rendered key's row (with its blob's digest); False if the blob cannot be read."""
    digest = _blob_digest(store.blob_path(reply.render_key))
    if digest is None:
        return False
    info = reply.info
    writer.add({"render_key": reply.render_key, "seconds": info.seconds, "valid": info.valid, "width": info.width,
                "height": info.height, "created_at": utc_now(), DIGEST_COLUMN: digest})
    return True


def _record_parts(writer, job: Job, info: RenderInfo) -> None:
    """Add the job's visible parts (its worker rendered the UV pass: ``info.parts``)."""
    writer.add({"parts_key": job.parts_key, "render_key": job.render_key, "layout": PARTS_LAYOUT,
                **info.parts, "created_at": utc_now()})


def _groups(plan: Plan, store: Store, todo: list[Job], cached: frozenset[str] | set[str] = frozenset()
            ) -> list[list[RenderJob]]:
    """Jobs for the workers, grouped by scene; a job whose render is in ``cached`` (there for
    its UV pass) carries no blob path."""
    spec = plan.spec
    controls = {c.id: c.control for c in spec.controls if c.control.stage == "render"}
    ordered = sorted(controls.values(), key=lambda c: c.order)
    environments = {e.name: e for e in spec.spec.environments}
    meshes: dict[str, str] = {}
    by_scene: dict[tuple[str, str], list[RenderJob]] = defaultdict(list)
    for job in todo:
        if job.object not in meshes:
            meshes[job.object] = str(materialise_mesh(spec.meshes[job.object], store.root))
        env = environments[job.environment]
        by_scene[job.scene].append(RenderJob(
            render_key=job.render_key,
            mesh=meshes[job.object],
            environment=EnvironmentRef(hdri=spec.hdris[env.name], color=env.color, strength=env.strength),
            controls=tuple((c, c.params(job.values[c.id])) for c in ordered if c.id in job.values),
            blob=None if job.render_key in cached else str(store.blob_path(job.render_key)),
        ))
    groups = []
    for scene in sorted(by_scene):
        jobs = by_scene[scene]
        groups += [jobs[i : i + GROUP_SIZE] for i in range(0, len(jobs), GROUP_SIZE)]
    return groups


def _blob_digest(path: Path) -> str | None:
    try:
        return sha256_bytes(path.read_bytes())
    except OSError:
        return None


def _user_error(plan: Plan, job: Job, message: str) -> UserError:
    """A worker's user error as one line naming the spec file, the key to fix and how."""
    spec = plan.spec
    problem = " ".join(message.split())  # Blender's messages may span lines
    hdri = spec.hdris.get(job.environment)
    objects = [o.name for o in spec.spec.objects]
    environments = [e.name for e in spec.spec.environments]
    if hdri and hdri in message:
        key = f"environments[{environments.index(job.environment)}].hdri"
        fix = "give an .exr/.hdr image Blender can read"
    elif "cannot write" in message:
        return UserError(problem)
    else:
        key = f"objects[{objects.index(job.object)}].mesh"
        fix = "check that the file opens in Blender, or export the mesh again"
    return SpecError(str(spec.path), key, f"{problem.rstrip('.')} ({job.object!r} in {job.environment!r}); {fix}")
