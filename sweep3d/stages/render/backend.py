"""The renderer seam: what an engine (``[render] engine``) is to the rest of sweep3d.

An engine is one folder under ``stages/render/`` (``cycles/``, ``mitsuba/``) with a
:class:`Backend`: it builds a worker's :class:`RenderScene`, which loads a job's object and world
(``prepare``), applies its :class:`~.state.SceneState` (``pose_scene``), renders and reads the
passes it declares; and it says, once per control type, what it cannot render
(:meth:`Backend.supports`), so that ``plan`` refuses it in one line before anything renders.
Backends are registered by engine name in :data:`~.backends.BACKENDS`.

Plain Python: a backend's module imports neither bpy nor mitsuba (its :meth:`Backend.scene` does,
in the worker).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from sweep3d.core import SpecError

if TYPE_CHECKING:
    import numpy as np

    from sweep3d.spec import LoadedSpec
    from sweep3d.stages.render.render_log import RenderLog
    from sweep3d.stages.render.state import SceneState
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, Look, RenderSettings

#: Why a backend cannot render a control with these parameter spaces (its values by label), or None.
Support = Callable[[Mapping[str, Any]], "str | None"]


class RenderScene(Protocol):
    """A render worker's scene, kept from job to job (what ``worker.render_job`` drives).

    Attributes:
        load_seconds: what the current job's switch of object or world cost (0: none).
        parts: what the UV pass saw in the latest render (None without one).
        truth_pass: the truth passes' reader (``truth`` numbers, ``blobs``), None without them.
    """

    load_seconds: float
    parts: dict[str, Any] | None
    truth_pass: Any

    def prepare(self, mesh_path: str, environment: EnvironmentRef, look: Look | None = None) -> None:
        """Make the job's object (as its look shows it) and world current, loading each the first time."""

    def pose_scene(self, state: SceneState) -> None:
        """Apply the job's state (pose, camera, lights, world, materials, props)."""

    def render(self) -> np.ndarray:
        """The image: float32 (H, W, 3), sRGB values in [0, 1]."""

    def render_png(self) -> bytes:
        """The blob: the image as an 8-bit RGB PNG, and the passes read."""

    def rebuild_if_stale(self) -> None:
        """Start afresh when a control's ``edit`` changed data the scene held (after the reply)."""


def can_be(spaces: Mapping[str, Any], param: str, test: Callable[[Any], bool]) -> bool:
    """Whether a control's ``param`` takes, somewhere in its space, a value passing ``test``."""
    space = spaces.get(param)
    return space is not None and any(test(v) for v in space.values())


def refuse_when(param: str, test: Callable[[Any], bool], reason: str) -> Support:
    """A :data:`Support` refusing a control whose ``param`` can take a value passing ``test``."""
    return lambda spaces: reason if can_be(spaces, param, test) else None


class Backend(ABC):
    """One renderer. Subclasses set the class attributes and :meth:`scene`; the rest has defaults.

    Attributes:
        name: the engine's name in ``[render] engine``, in keys and in messages.
        title: the renderer's own name, in messages ("Mitsuba").
        passes: the passes besides RGB it renders ("uv": part visibility; "mask", "depth").
        devices: what it renders on (``[render] device`` resolved); the first is where ``auto`` falls back.
        edits_scene: whether a control's ``edit()`` (Blender's live scene) can run.
        ignored_settings: ``[render]`` settings it does not read, and what each is to the engine
            that does: set away from its default, refused (it would change nothing).
        support: per control type name, what it cannot render of that control (:data:`Support`);
            a control not named is rendered as its state says.
        seconds_224: (seconds per sample, seconds per render besides samples and the denoiser)
            at 224² on 2 CPU cores, for ``plan``'s estimate.
    """

    name: ClassVar[str]
    title: ClassVar[str]
    passes: ClassVar[frozenset[str]] = frozenset({"uv", "mask", "depth"})
    devices: ClassVar[tuple[str, ...]] = ("cpu",)
    edits_scene: ClassVar[bool] = False
    ignored_settings: ClassVar[Mapping[str, str]] = {}
    support: ClassVar[Mapping[str, Support]] = {}
    seconds_224: ClassVar[tuple[float, float]]

    @abstractmethod
    def scene(self, settings: RenderSettings, scratch: Path, log: RenderLog | None = None,
              gpu: int | None = None) -> RenderScene:
        """Build a worker's scene (in the worker: this is where bpy or mitsuba is imported)."""

    def key(self) -> dict[str, Any] | None:
        """The engine's part of every render key (None: none, keys as they were before engines)."""
        return {"name": self.name}

    def variant(self) -> str:
        """The engine's variant, as its render keys name it ("": none)."""
        return ""

    def note(self) -> str | None:
        """A line a run says once before it renders with this engine (None: nothing to say)."""
        return None

    def plan_device(self, device: str) -> str:
        """The device renders are keyed and made on, for ``device`` resolved (``auto`` already
        resolved on this machine): one this engine cannot use falls back to its first."""
        return device if device in self.devices else self.devices[0]

    def supports(self, control: Any, spaces: Mapping[str, Any]) -> str | None:
        """Why this engine cannot render ``control`` with these parameter spaces (None: it can)."""
        if control.edits_scene and not self.edits_scene:
            return f"its edit() changes Blender's scene, which {self.title} does not have"
        check = self.support.get(control.type_name)
        return check(spaces) if check is not None else None

    def check_setup(self, spec: LoadedSpec) -> None:
        """Refuse (:class:`SpecError`) what this machine or ``[render]`` lacks for the engine (default: nothing)."""
        return None

    def check_objects(self, spec: LoadedSpec) -> None:
        """Refuse (:class:`SpecError`) an object the engine cannot read (default: none)."""
        return None

    def check(self, spec: LoadedSpec) -> None:
        """Refuse, in one line naming the key and the engine, what the spec asks that this engine
        cannot render: its set-up, a pass it lacks, a setting it ignores set, an object, a control.

        Raises:
            SpecError: the first such thing.
        """
        path = str(spec.path)
        self.check_setup(spec)
        if spec.report.part_visibility and "uv" not in self.passes:
            raise SpecError(path, "report.part_visibility", f"part visibility needs Cycles' UV pass; the {self.name} "
                                                            "engine cannot render it (set it false)")
        for name, what in self.ignored_settings.items():
            value = getattr(spec.render, name)
            if value != type(spec.render).model_fields[name].default:
                raise SpecError(path, f"render.{name}", f"{name} = {value!r} is a Cycles setting ({what}), so it "
                                                        f"would change nothing with engine \"{self.name}\"; remove it")
        self.check_objects(spec)
        for index, inst in enumerate(spec.controls):
            if inst.control.stage != "render":
                continue
            problem = self.supports(inst.control, inst.spaces)
            if problem:
                raise SpecError(path, f"controls[{index}]", f"control {inst.control.type_name!r} (id "
                                                            f"{inst.control.id!r}): {problem} with engine \"{self.name}\"")
