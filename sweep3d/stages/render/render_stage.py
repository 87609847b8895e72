"""The render stage: every render key the plan needs and the store lacks, grouped by scene.

A render counts as stored when it has a row and a blob; the driver drops a row whose blob has
gone and the key is rendered again. Each row records the SHA-256 of its blob, so readers can tell
a damaged blob from a good one. A job that fails because of the user's input (a mesh or HDRI
Blender cannot use, a full disk) stops the run with a one-line error naming the spec key.

Workers keep what they have loaded, so the stage orders scenes world by world and the pool
gives each worker a contiguous share of that order (see :func:`_groups`).

When the report asks for part visibility, workers also write a UV pass and each render records
which parts of the object it shows (the ``parts`` table, one row per ``parts_key``). A render
that is cached but lacks that row is rendered again for the pass only: its blob is kept.

The truth passes (object mask, depth; see :mod:`sweep3d.core.truth`) work the same way, when
something needs them (:func:`sweep3d.driver.passes.needed_passes`): each render adds a
``truths`` row under its ``truth_key`` (box, visible pixels, visible fraction, the digests of
its blobs), and its blobs go to ``blobs/ab/<truth_key>.mask.png`` / ``.depth.npz``, written here
in the parent (workers return their bytes, local and Ray alike) before the row is yielded. A
cached render whose truth row or blobs are missing is rendered again for the passes only.
"""

from __future__ import annotations

import logging
from collections import Counter, defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import pyarrow as pa

from sweep3d.assets import materialise_mesh
from sweep3d.cache import DIGEST_COLUMN, TRUTH_BLOBS, Store, atomic_write, sha256_bytes, utc_now
from sweep3d.core import BLOB_SUFFIX, PARTS_LAYOUT, PluginError, SpecError, UserError
from sweep3d.driver import Computed, Feed, Job, JobList, Plan, needed_passes, truth_passes
from sweep3d.spec import LoadedSpec, RenderSpec
from sweep3d.stages.render.device import worker_count
from sweep3d.stages.render.pool import RenderPool
from sweep3d.stages.render.worker_protocol import (
    EnvironmentRef,
    Look,
    RenderExecutor,
    RenderInfo,
    RenderJob,
    RenderReply,
    RenderSettings,
    WorkerLimits,
)

log = logging.getLogger("sweep3d.render")

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
TRUTHS_SCHEMA = pa.schema([
    ("truth_key", pa.string()), ("render_key", pa.string()), ("passes", pa.list_(pa.string())),
    ("gt_x0", pa.int32()), ("gt_y0", pa.int32()), ("gt_x1", pa.int32()), ("gt_y1", pa.int32()),
    ("visible_pixels", pa.int64()), ("silhouette_pixels", pa.int64()), ("visible_fraction", pa.float64()),
    ("silhouette", pa.string()), ("framed_pixels", pa.int64()), ("truth_seconds", pa.float64()),
    ("mask_sha256", pa.string()), ("depth_sha256", pa.string()), ("created_at", pa.timestamp("us")),
])


@dataclass(frozen=True)
class Executor:
    """Where renders run: ``local`` worker processes (the default) or a ``ray`` cluster
    (``address`` of an existing cluster, or None for a local one on loopback)."""

    kind: str = "local"
    address: str | None = None

    def pool(self, settings: RenderSettings, workers: int, spec: RenderSpec) -> RenderExecutor:
        """A fresh executor of this kind (``spec``'s timeouts and worker limits apply to local
        workers only)."""
        if self.kind == "ray":
            from sweep3d.stages.render.ray_pool import RayRenderPool

            return RayRenderPool(settings, workers, self.address)
        return RenderPool(settings, workers, spec.timeout, WorkerLimits.from_spec(spec), spec.edit_timeout)


LOCAL = Executor()


def render_settings(plan: Plan) -> RenderSettings:
    """The [render] settings with the resolved frame and device and the passes to write, as workers
    need them (only those something needs: see :func:`needed_passes`)."""
    return RenderSettings.from_spec(plan.spec.render, plan.framing, needed_passes(plan.spec), plan.device)


class RenderStage:
    """Renders in Blender workers on ``executor`` (local processes, or Ray actors).

    Args:
        timings: when given, each render made here adds its worker's :class:`RenderInfo` under
            its key (``bench`` reads scene-load time apart from render time there; the renders
            table keeps only the whole job's seconds).
        keep_open: keep the local workers between :meth:`compute` calls (the caller then closes
            the stage, :meth:`close`): a caller computing many small plans in turn (``explain``'s
            rounds) pays Blender's start once, not once a plan.
    """

    name = "render"
    table = "renders"
    owns_blobs = True
    side_tables = {"parts": PARTS_SCHEMA, "truths": TRUTHS_SCHEMA}

    def __init__(self, executor: Executor = LOCAL, timings: dict[str, RenderInfo] | None = None,
                 keep_open: bool = False) -> None:
        self.executor = executor
        self.timings = timings
        self.keep_open = keep_open and executor.kind == "local"
        self._warm: tuple[RenderSettings, RenderExecutor] | None = None  # see warm_up
        self._ending: list[RenderExecutor] = []  # closed without waiting: see close

    def warm_up(self, plan: Plan) -> None:
        """Start ``plan``'s first local render worker now, so that Blender's start overlaps the
        caller's own work (a run checks its model meanwhile); :meth:`compute` renders with it.
        The caller closes the stage (:meth:`close`) whether or not it computes."""
        if self.executor.kind != "local" or self._warm is not None:
            return
        settings, spec = render_settings(plan), plan.spec.render
        pool = self.executor.pool(settings, worker_count(spec, plan.device), spec)
        pool.prestart()
        self._warm = settings, pool

    def close(self) -> None:
        """Stop a worker started by :meth:`warm_up` that no :meth:`compute` used (or kept open),
        and wait until the workers of finished computes have ended."""
        if self._warm is not None:
            self._warm[1].close()
            self._warm = None
        ending, self._ending = self._ending, []
        for pool in ending:
            pool.join()

    def schema(self, plan: Plan) -> pa.Schema:
        return RENDERS_SCHEMA

    def key(self, job: Job) -> str:
        return job.render_key

    def keys_of(self, jobs: JobList) -> list[str | None]:
        return jobs.key_column("render_key")

    def upstream(self, job: Job) -> None:
        return None

    def incomplete(self, plan: Plan, store: Store, cached: set[str]) -> set[str]:
        """Cached renders whose UV-pass parts (when the report asks for them) or truth row and
        blobs (when something needs the truth passes) the store lacks."""
        out: set[str] = set()
        if plan.spec.report.part_visibility:
            have = store.keys("parts")
            out |= {j.render_key for j in plan.jobs if j.render_key in cached and j.parts_key not in have}
        passes = truth_passes(plan.spec)
        if passes:
            have = store.keys("truths")
            wanted = {j.truth_key: j.render_key for j in plan.jobs if j.render_key in cached}
            for suffix in (BLOB_SUFFIX[p] for p in passes):
                have &= store.existing_blobs(have & set(wanted), suffix)
            out |= {render for truth, render in wanted.items() if truth not in have}
        return out

    def compute(self, todo: Feed, plan: Plan, store: Store) -> Iterator[Computed]:
        stored = {j.render_key for j in todo if store.blob_path(j.render_key).exists()} & store.keys("renders")
        groups = _groups(plan, store, todo, stored)
        jobs = {j.render_key: j for j in todo}
        spec, settings = plan.spec.render, render_settings(plan)
        warm, self._warm = self._warm, None
        if warm is not None and warm[0] == settings:
            pool = warm[1]
        else:
            if warm is not None:  # planned again with other settings: not this worker
                warm[1].close()
            workers = worker_count(spec, plan.device)  # a pool starts only the workers its groups need
            pool = self.executor.pool(settings, workers if self.keep_open else min(workers, len(groups)), spec)
        kept = done = False
        try:
            yield from self._replies(pool.run(groups), plan, store, jobs, stored)
            if pool.recycled:
                log.warning(recycled_note(spec, pool.recycled))
                pool.recycled.clear()
            kept, done = self.keep_open, True
        finally:
            if kept:  # warm for the next compute; close() stops it
                self._warm = settings, pool
            elif done:  # the stages downstream go on while Blender exits; close() waits for it
                pool.close(wait=False)
                self._ending.append(pool)
            else:
                pool.close()

    def _replies(self, replies: Iterator[RenderReply], plan: Plan, store: Store, jobs: dict[str, Job],
                 stored: set[str]) -> Iterator[Computed]:
        """What each worker's reply computed: the render's row and its side rows, or its error."""
        warned = False
        for reply in replies:
            job = jobs[reply.render_key]
            if not reply.ok:
                if reply.kind == "plugin":
                    raise PluginError(reply.error or "a control failed", reply.details)
                if reply.kind == "user":
                    raise _user_error(plan, job, reply.error or "")
                yield Computed(job.render_key, error=reply.error or "the render failed")
                continue
            if self.timings is not None:
                self.timings[job.render_key] = reply.info
            if reply.info.rebuilt and not warned:
                warned = True
                log.warning(rebuilt_warning(plan, reply.info.rebuilt))
            row = None
            if job.render_key not in stored:  # else it was rendered again for its UV pass only
                row = _row(store, reply)
                if row is None:
                    yield Computed(job.render_key, error="the worker reported success but its blob cannot be read")
                    continue
            side = {"parts": _parts_row(job, reply)} if job.parts_key is not None else {}
            if job.truth_key is not None:
                truth = _truth_row(store, job, reply)
                if truth is None:
                    yield Computed(job.render_key, error=no_truth_error(plan, reply))
                    continue
                side["truths"] = truth
            yield Computed(job.render_key, row, side)


def _row(store: Store, reply: RenderReply) -> dict | None:
    """A rendered key's row (with its blob's digest); None if the blob cannot be read."""
    digest = _blob_digest(store.blob_path(reply.render_key))
    if digest is None:
        return None
    info = reply.info
    return {"render_key": reply.render_key, "seconds": info.seconds, "valid": info.valid, "width": info.width,
            "height": info.height, "created_at": utc_now(), DIGEST_COLUMN: digest}


def _parts_row(job: Job, reply: RenderReply) -> dict:
    """The job's visible parts (its worker rendered the UV pass: ``info.parts``)."""
    return {"parts_key": job.parts_key, "render_key": job.render_key, "layout": PARTS_LAYOUT,
            **reply.info.parts, "created_at": utc_now()}


def _truth_row(store: Store, job: Job, reply: RenderReply) -> dict | None:
    """Write the job's truth blobs (mask, depth) and return its ``truths`` row with their digests;
    None when the worker sent none. Blobs first: a row on disk always has its blobs."""
    if reply.truth is None or reply.info.truth is None:
        return None
    row = {"truth_key": job.truth_key, "render_key": job.render_key, "passes": sorted(reply.truth),
           **{k: v for k, v in reply.info.truth.items() if k in TRUTHS_SCHEMA.names}, "created_at": utc_now()}
    for name, data in reply.truth.items():
        suffix = BLOB_SUFFIX[name]
        atomic_write(store.blob_path(job.truth_key, suffix), data)
        row[TRUTH_BLOBS[suffix]] = sha256_bytes(data)
    return row


def _groups(plan: Plan, store: Store, todo: list[Job], stored: set[str]) -> list[list[RenderJob]]:
    """Jobs for the workers, grouped by scene and ordered world by world (then object by object):
    a worker keeps every object and world it has loaded, but Cycles rebuilds the world's
    importance map whenever the world changes, so a worker given a contiguous share of this order
    changes world as rarely as it can. A job whose render is ``stored`` (there for its UV pass)
    carries no blob path."""
    spec = plan.spec
    ordered = sorted((c.control for c in spec.controls if c.control.stage == "render"), key=lambda c: c.order)
    environments = {e.name: e for e in spec.environments}
    looks = {o.name: Look.of(o) for o in spec.objects}
    meshes: dict[str, str] = {}
    by_scene: dict[tuple[str, str], list[RenderJob]] = defaultdict(list)
    for job in todo:
        if job.object not in meshes:
            meshes[job.object] = str(materialise_mesh(spec.meshes[job.object], store.root))
        env = environments[job.environment]
        by_scene[job.environment, job.object].append(RenderJob(
            render_key=job.render_key,
            mesh=meshes[job.object],
            environment=EnvironmentRef(hdri=spec.hdris[env.name], color=env.color, strength=env.strength,
                                       key_light=env.key_light),
            controls=tuple((c, c.params(job.values[c.id])) for c in ordered if c.id in job.values),
            blob=None if job.render_key in stored else str(store.blob_path(job.render_key)),
            look=looks[job.object],
            object_name=job.object,
            environment_name=job.environment,
        ))
    groups = []
    for scene in sorted(by_scene):
        jobs = by_scene[scene]
        groups += [jobs[i : i + GROUP_SIZE] for i in range(0, len(jobs), GROUP_SIZE)]
    return groups


def no_truth_error(plan: Plan, reply: RenderReply) -> str:
    """Why a job that needs its truth passes has none: the controls whose ``edit`` changed what
    the scene held, when one did (the scene was rebuilt around the job), else the worker's settings."""
    changed = reply.info.rebuilt if reply.info is not None else ()
    if changed:
        names = ", ".join(repr(c.control.type_name) for c in plan.spec.controls
                          if c.control.stage == "render" and c.control.edits_scene)
        return (f"the worker rendered no truth passes: the edit() of control {names} changed what the scene held "
                f"({', '.join(changed[:3])}{', …' if len(changed) > 3 else ''}) and the scene was rebuilt before "
                "the passes were read")
    return "the worker rendered no truth passes though the run asked for them (a bug: please report it)"


def rebuilt_warning(plan: Plan, changed: tuple[str, ...]) -> str:
    """The one line said when a control's ``edit`` changed data the scene held (see ``scene_edit``)."""
    names = ", ".join(repr(c.control.type_name) for c in plan.spec.controls
                      if c.control.stage == "render" and c.control.edits_scene)
    return (f"warning: the edit() of control {names} changed what the scene already held ({', '.join(changed[:3])}"
            f"{', …' if len(changed) > 3 else ''}), so the render worker rebuilds its scene after each such job "
            "(slow: every mesh and world is loaded again); change copies instead (material.copy(), then assign "
            "the copy), or use the state's material edits")


def recycled_note(spec: RenderSpec, recycled: Counter[str]) -> str:
    """The one line said when workers were replaced between jobs: how many, and which limit."""
    why = {"memory": f"holding more than render.worker_memory = {spec.worker_memory} MB",
           "jobs": f"after render.worker_jobs = {spec.worker_jobs} jobs"}
    parts = ", ".join(f"{n} {why[reason]}" for reason, n in sorted(recycled.items()))
    total = sum(recycled.values())
    return (f"note: {total} render worker{'s were' if total > 1 else ' was'} replaced by a fresh one between jobs "
            f"({parts}); each replacement loads Blender and its scene again")


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
    environments = [e.name for e in spec.environments]
    if hdri and hdri in message:
        key = f"environments[{environments.index(job.environment)}].hdri"
        fix = "give an .exr/.hdr image Blender can read"
    elif "cannot write" in message:
        return UserError(problem)
    elif problem.startswith("the material control's target"):
        index = next((i for i, c in enumerate(spec.controls) if c.control.type_name == "material"
                      and "target" in c.spaces), 0)
        key, fix = f"controls[{index}].target", "name one of its materials, or leave target out for all of them"
    else:
        return object_error(spec, job.object, message, f" ({job.object!r} in {job.environment!r})")
    return SpecError(str(spec.path), key, f"{problem.rstrip('.')} ({job.object!r} in {job.environment!r}); {fix}")


def object_error(spec: LoadedSpec, name: str, message: str, context: str = "") -> SpecError:
    """A worker's user error about object ``name`` as one line naming the key to fix: its ``parts``
    or material overrides (stages/render/cycles/blender_looks.py says the fix), else its mesh."""
    problem = " ".join(message.split())
    index = [o.name for o in spec.objects].index(name)
    if problem.startswith(("no object ", "the parts ")):
        return SpecError(str(spec.path), f"objects[{index}].parts", problem)
    if problem.startswith("no material ") or "Principled BSDF" in problem:
        key = "materials" if problem.startswith("no material ") or not spec.objects[index].material else "material"
        return SpecError(str(spec.path), f"objects[{index}].{key}", problem)
    return SpecError(str(spec.path), f"objects[{index}].mesh", f"{problem.rstrip('.')}{context}; check that the file "
                                                               "opens in Blender, or export the mesh again")
