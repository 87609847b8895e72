"""The engines ``[render] engine`` may name, by name: what was a branch on the engine's name.

The spec loader checks the name against :data:`BACKENDS` (handed to it in the catalogue), the
planner asks the spec's backend what it refuses, its part of the render key and its device, and
a worker asks it for its scene. A new engine is a folder with a :class:`~.backend.Backend`,
registered here (a test registers its own).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from sweep3d.core import Registry, UserError
from sweep3d.spec import RenderSpec
from sweep3d.stages.render.backend import Backend
from sweep3d.stages.render.cycles.backend import CyclesBackend
from sweep3d.stages.render.mitsuba.backend import MitsubaBackend

if TYPE_CHECKING:
    from sweep3d.spec import LoadedSpec

#: The engines by name (Cycles is ``[render] engine``'s default).
BACKENDS: Registry[Backend] = Registry("engine")
for _backend in (CyclesBackend(), MitsubaBackend()):
    BACKENDS.register(_backend.name)(_backend)


def backend(engine: str) -> Backend:
    """The backend registered as ``engine`` (a spec's was checked when it was loaded).

    Raises:
        UserError: no engine of that name (with the valid ones); a ``module:Name`` is none either.
    """
    if engine not in BACKENDS:
        raise UserError(f"unknown engine {engine!r}; use one of {', '.join(BACKENDS.names())}")
    return BACKENDS.get(engine)


def check_engine(spec: LoadedSpec) -> None:
    """Refuse, in one line naming the key and the engine, what the spec's engine cannot render
    (:meth:`Backend.check`)."""
    backend(spec.render.engine).check(spec)


def engine_key(engine: str) -> dict[str, Any] | None:
    """The engine's part of every render key: None for Cycles (its keys stay as they were)."""
    return backend(engine).key()


def plan_device(engine: str, device: str) -> str:
    """The device renders are keyed and made on with ``engine`` (Mitsuba: the CPU, whatever
    ``auto`` finds; an explicit GPU is refused by :func:`check_engine`)."""
    return backend(engine).plan_device(device)


def variant_note(engine: str) -> str | None:
    """The line a run says once before it renders with ``engine`` (Mitsuba's slower variant)."""
    return backend(engine).note()


def cycles_only_defaults(engine: str) -> dict[str, Any]:
    """The settings ``engine`` ignores, at their defaults, for a spec rendering with it that
    includes a Cycles spec (``realism score --engine``): nothing for Cycles itself."""
    return {name: RenderSpec.model_fields[name].default for name in backend(engine).ignored_settings}
