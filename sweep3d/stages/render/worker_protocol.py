"""What crosses the boundary between the render stage and its workers (processes or Ray actors).

Settings, jobs and replies are frozen dataclasses rather than dicts and positional tuples, so a
new field is one edit and no reader depends on a position. Everything here pickles (a job's
control instances and pydantic params included) and imports neither bpy nor torch: the parent
process never loads Blender.

A local worker receives a list of :class:`RenderJob` (one scene group) or None to stop, and
answers :class:`Ready` (or :class:`Fatal`) once, then per job :class:`Started` (and
:class:`Editing` around its controls' ``edit``) and a :class:`RenderReply`, and :class:`Idle`
after each list, or :class:`Retired` after a reply when it reached a :class:`WorkerLimits` limit
(it then exits).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, Literal, Protocol, Self

from sweep3d.spec import KeyLightSpec, MaterialSpec, ObjectSpec, RenderSpec
from sweep3d.stages.render.backends import backend

if TYPE_CHECKING:
    from pydantic import BaseModel

    from sweep3d.spec import Framing
    from sweep3d.stages.render.controls.rendered_control import RenderedControl

_SPEC = RenderSpec()  # the defaults below are the spec's, so a test's settings render as a spec's


@dataclass(frozen=True)
class RenderSettings:
    """How every render of a run is made; a worker's Blender scene is configured from it once.

    Args:
        resolution: the square frame's side in pixels.
        crop: the centre square actually rendered and stored (None: the whole frame).
        passes: extra passes beside the RGB image ("uv": the parts seen, for part visibility;
            "mask", "depth": the truth passes, see ``sweep3d.core.truth``).
        threads: Cycles threads per worker; 0 = all cores.
        device: what renders: "cpu", "cuda" or "optix" (``[render] device`` resolved: never
            "auto", see ``stages.render.device``).
        engine: the renderer (``[render] engine``): the worker builds its backend's scene
            (``stages.render.backends``); every engine renders the same jobs.
    """

    resolution: int
    crop: int | None = None
    samples: int = _SPEC.samples
    denoise: bool = _SPEC.denoise
    denoise_prefilter: Literal["fast", "accurate", "none"] = _SPEC.denoise_prefilter
    max_bounces: int = _SPEC.max_bounces
    adaptive_threshold: float = _SPEC.adaptive_threshold
    seed: int = _SPEC.seed
    threads: int = _SPEC.threads
    passes: tuple[str, ...] = ()
    device: str = "cpu"
    dither: float = _SPEC.dither
    world_sampling: Literal["automatic", "manual", "none"] = _SPEC.world_sampling
    world_map_resolution: int = _SPEC.world_map_resolution
    engine: str = _SPEC.engine  # a registered backend's name: which scene the worker builds
    variant: str = ""  # the engine's variant, as its render keys name it (Mitsuba's; "" for Cycles)

    @classmethod
    def from_spec(cls, spec: RenderSpec, framing: Framing, passes: Iterable[str] = (),
                  device: str = "cpu") -> RenderSettings:
        """The ``[render]`` settings of the same name, with the resolved frame, the passes and the
        resolved device.

        The frame replaces ``resolution`` because the spec's may be "model", resolved elsewhere;
        the device replaces ``device``, which may be "auto".
        """
        shared = {f.name: getattr(spec, f.name) for f in fields(cls) if f.name in RenderSpec.model_fields}
        variant = backend(spec.engine).variant()  # the key's, wherever the worker runs
        return cls(**{**shared, "resolution": framing.size, "crop": framing.crop, "passes": tuple(passes),
                      "device": device, "variant": variant})


@dataclass(frozen=True)
class WorkerLimits:
    """When a local worker stops between jobs (after its reply), for a fresh one to go on: a
    worker's memory only grows (what it keeps loaded, Blender's own caches and leaks).

    Args:
        memory_mb: ``[render] worker_memory``: the resident MB it may hold after a job; 0 = no limit.
        jobs: ``[render] worker_jobs``: the jobs it renders; 0 = no limit.
    """

    memory_mb: int = 0
    jobs: int = 0

    @classmethod
    def from_spec(cls, spec: RenderSpec) -> WorkerLimits:
        return cls(spec.worker_memory, spec.worker_jobs)

    def reached(self, jobs: int, resident_mb: float | None) -> Literal["memory", "jobs"] | None:
        """Which limit a worker that rendered ``jobs`` and holds ``resident_mb`` (None: unknown,
        no check) has reached, memory first; None when neither."""
        if self.memory_mb and resident_mb is not None and resident_mb > self.memory_mb:
            return "memory"
        if self.jobs and jobs >= self.jobs:
            return "jobs"
        return None


NO_LIMITS = WorkerLimits()  # a worker renders until it is stopped


@dataclass(frozen=True)
class EnvironmentRef:
    """A job's world: an HDRI file (a local path, or a Ray pack reference) or a plain colour, with
    a plain colour's key light (None: lit by its uniform light alone)."""

    hdri: str | None = None
    color: tuple[float, float, float] | None = None
    strength: float = 1.0
    key_light: KeyLightSpec | None = None


#: A material override as (input, value) pairs, sorted: hashable, so a worker can key objects by it.
Overrides = tuple[tuple[str, Any], ...]


def overrides(material: MaterialSpec | None) -> Overrides:
    """The values a ``[objects] material`` table gives, as sorted pairs (colours as tuples)."""
    part = material.key_part() if material is not None else {}
    return tuple(sorted((k, tuple(v) if isinstance(v, list) else v) for k, v in part.items()))


@dataclass(frozen=True)
class Look:
    """How an object is shown beyond what its file says: which of its objects (``parts``; None:
    all), material overrides for all of their materials and per material name, and smoothing by
    angle. A worker keeps one import per (mesh, look)."""

    parts: tuple[str, ...] | None = None
    material: Overrides = ()
    materials: tuple[tuple[str, Overrides], ...] = ()
    auto_smooth: float | None = None

    @classmethod
    def of(cls, obj: ObjectSpec) -> Look | None:
        """The spec object's look; None when it has none (the object renders as its file says)."""
        if obj.look_key() is None:
            return None
        named = tuple(sorted((name, overrides(m)) for name, m in obj.materials.items() if overrides(m)))
        parts = tuple(sorted(obj.parts)) if obj.parts else None  # the order changes nothing rendered
        return cls(parts, overrides(obj.material), named, obj.auto_smooth)


@dataclass(frozen=True)
class RenderJob:
    """One render: the scene, the rendered controls in application order, and where it goes.

    Args:
        look: the object's parts, material overrides and smoothing (None: as its file says).
        blob: the store path the PNG is written to; None when the render is already stored and
            the job is here only for its UV or truth passes.
    """

    render_key: str
    mesh: str
    environment: EnvironmentRef
    controls: tuple[tuple[RenderedControl, BaseModel], ...] = ()
    blob: str | None = None
    look: Look | None = None
    object_name: str = ""  # the spec's names of the scene, for a control's ``edit``
    environment_name: str = ""


@dataclass(frozen=True)
class RenderInfo:
    """What a finished render reports; ``parts`` is what the UV pass saw (see ``parts.part_counts``).

    Args:
        seconds: the whole job, as the renders table records it.
        load_seconds: the part of ``seconds`` spent switching to the job's scene (a mesh import,
            a world and its HDRI, Cycles' BVH and importance map before the first sample); 0 when
            the worker already showed it. For reporting only (``bench``): in no key, no table.
    """

    seconds: float
    valid: bool
    width: int
    height: int
    parts: dict[str, Any] | None = None
    load_seconds: float = 0.0
    truth: dict[str, Any] | None = None  # the truth passes' numbers (``sweep3d.core.truth.ground_truth``)
    #: What a control's ``edit`` changed of the data the scene held before (the worker then rebuilt
    #: its scene, which is slow: the render stage says so once); empty when edits only added things.
    rebuilt: tuple[str, ...] = ()

    @property
    def render_seconds(self) -> float:
        """The steady-state part: ``seconds`` without the scene load."""
        return max(self.seconds - self.load_seconds, 0.0)


@dataclass(frozen=True)
class RenderReply:
    """The outcome of one job.

    Args:
        info: set when ``ok``.
        kind: "user" when the spec's input (a mesh, an HDRI) or a full disk failed the job, which
            stops the run with a user error; "plugin" when a user's control raised (``error`` is
            its one line, ``details`` the traceback); "internal" otherwise.
        png: the pixels, when the worker keeps them for the caller to write (Ray: the driver
            writes every blob, so workers need no shared file system).
        truth: the truth passes' blobs by pass ("mask", "depth"), always returned: the render
            stage writes them (and records their digests) in the parent, local or Ray alike.
    """

    render_key: str
    ok: bool
    info: RenderInfo | None = None
    error: str | None = None
    kind: Literal["user", "plugin", "internal"] = "internal"
    png: bytes | None = None
    truth: dict[str, bytes] | None = None
    details: str = ""


@dataclass(frozen=True)
class Ready:
    """A worker has its Blender scene and waits for jobs."""

    pid: int


@dataclass(frozen=True)
class Fatal:
    """A worker could not build its scene; the run fails (``user``: with a user error, exit 2,
    such as a ``[render] device`` it cannot use)."""

    message: str
    user: bool = False


@dataclass(frozen=True)
class Retired:
    """A worker reached one of its :class:`WorkerLimits` after a job's reply and exits; the pool
    gives the rest of its list to a fresh worker."""

    reason: Literal["memory", "jobs"]


@dataclass(frozen=True)
class Started:
    """A worker began a job: the pool times it from now and blames it if the worker dies."""

    render_key: str


@dataclass(frozen=True)
class Editing:
    """A worker calls the ``edit`` of the job's control ``control`` (its id), or has returned from
    the job's last one (None): the pool times each edit on its own (``[render] edit_timeout``), and
    names a user's control whose ``edit`` the worker died in.
    """

    render_key: str
    control: str | None


@dataclass(frozen=True)
class Idle:
    """A worker finished its list of jobs and can take another."""


class RenderExecutor(Protocol):
    """Runs render jobs somewhere (local processes, a Ray cluster); the render stage needs no more."""

    def __enter__(self) -> Self: ...

    def __exit__(self, *exc: object) -> None: ...

    #: Workers replaced by fresh ones between jobs, by the limit they reached ("memory", "jobs").
    recycled: Counter[str]

    def run(self, groups: list[list[RenderJob]]) -> Iterator[RenderReply]:
        """Render every job of every group (a group shares one scene), yielding one reply per job."""
        ...

    def prestart(self) -> None:
        """Start the first worker ahead of :meth:`run`, where that can overlap other work."""
        ...

    def close(self, wait: bool = True) -> None:
        """Stop the workers and remove their scratch files (``wait``: before returning; else
        :meth:`join` waits for that)."""
        ...

    def join(self) -> None:
        """Wait for what a :meth:`close` without waiting left ending."""
        ...
