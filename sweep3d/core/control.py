"""The control plug-in base, shared by the render and postprocess stages.

A control declares its parameters as a pydantic model whose defaults are *neutral*: a control
whose values equal its defaults leaves the image as it was, so it is dropped from the job's
cache keys (a spec that adds ``yaw = 0`` re-renders nothing). Rendered controls live in
``sweep3d.stages.render.controls`` and change the 3D scene; post controls live in
``sweep3d.stages.postprocess.controls`` and map one image to another. Each of those stages keeps
its own registry; the spec loader sees both through the catalogue it is handed.
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from typing import Annotated, Any, ClassVar, Iterator, Literal

import numpy as np
from pydantic import ConfigDict

from sweep3d.core.errors import PLUGIN_FAILURES, plugin_failure
from sweep3d.core.registry import code_identity, is_user_plugin
from sweep3d.core.typed import Typed


class _SpecRelativePath:
    """Marks a ``str`` parameter as a file: see :data:`SpecPath`."""


#: A parameter that names a file. The spec loader resolves it against the spec file's folder (as it
#: does meshes and HDRIs) and refuses a file that does not exist, naming the key.
SpecPath = Annotated[str, _SpecRelativePath()]


def is_spec_path(field: Any) -> bool:
    """Whether a pydantic field was declared as :data:`SpecPath`."""
    return any(isinstance(m, _SpecRelativePath) for m in getattr(field, "metadata", ()))


class ControlParams(Typed):
    """Base of every control's parameter model: unknown keys are errors, values are checked."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class Control:
    """One instance of a control in a spec (the same type may appear twice with different ids).

    Subclasses set ``Params`` (a :class:`ControlParams` model with neutral defaults), ``stage``
    and, for angles, ``periodic`` (parameter name → period) so that equal configurations hash
    equal (yaw 190° is yaw -170°).
    """

    stage: ClassVar[Literal["render", "post"]]
    Params: ClassVar[type[ControlParams]] = ControlParams
    periodic: ClassVar[dict[str, float]] = {}
    #: Bumped when the control's effect on pixels changes, so old cache entries are not reused.
    version: ClassVar[int] = 1
    #: Render passes the control needs beside the image ("mask", "depth"; see ``sweep3d.core.truth``).
    passes: ClassVar[tuple[str, ...]] = ()
    #: Parameters that stand for another in keys, as parameter → (the one it stands for, the others
    #: it is read with): the camera's ``fill`` is a ``zoom`` at its ``focal_length``. A spec gives one
    #: of the two, never both. Such a parameter is left out of a job's values unless given, and
    #: ``canonical`` (which folds it into the one it stands for) is the base class's without it,
    #: so the planner keys the control over arrays unless it, or one it is read with, is a range.
    folds: ClassVar[dict[str, tuple[str, ...]]] = {}
    #: The change to each parameter that a person would call invisible, as parameter → kind, for the
    #: stability check's scene neighbours (``sweep3d stability``): "angle" (degrees, ±``[stability]
    #: angle``), "hdri_rotation" (degrees), "distance" (a camera distance, ±a share), "closeness" (a
    #: value that grows as the camera nears, as ``zoom``: the distance ±a share) or "light" (a light's
    #: strength, ±a share). A rendered parameter without one is listed as not moved, with the reason.
    neighbour_steps: ClassVar[dict[str, str]] = {}

    def __init__(self, control_id: str, type_name: str) -> None:
        self.id = control_id
        self.type_name = type_name

    def params(self, values: dict[str, Any]) -> ControlParams:
        """Validate one job's values for this control into its ``Params`` model."""
        return self.Params(**values)

    def canonical(self, values: dict[str, Any]) -> dict[str, Any]:
        """Values in a canonical form: periodic parameters wrapped into (-period/2, period/2]."""
        out = dict(values)
        for name, period in self.periodic.items():
            if name in out and isinstance(out[name], (int, float)):
                out[name] = wrap_periodic(float(out[name]), period)
        return out

    def is_identity(self, values: dict[str, Any]) -> bool:
        """True when these values cannot change the image (they equal the neutral defaults)."""
        canon = self.canonical(values)
        neutral = self.canonical(self.Params().model_dump())
        return all(canon.get(k) == v for k, v in neutral.items())

    def key_part(self, values: dict[str, Any]) -> dict[str, Any]:
        """What of this control goes into a cache key: for a user's control (``module:Name``) also
        the identity of its code (``core.registry.code_identity``)."""
        part = {"type": self.type_name, "v": self.version, "values": self.canonical(values)}
        if is_user_plugin(self.type_name):
            part["code"] = code_identity(type(self))
        return part


def control_label(control: Control) -> str:
    """How messages name a control: its type as the spec gives it and its id (``control 'mod:Cut' (id 'Cut')``)."""
    return f"control {control.type_name!r} (id {control.id!r})"


@contextmanager
def blamed(control: Control, method: str) -> Iterator[None]:
    """Run a control's ``method`` (e.g. "apply()") so that a user's control that raises or exits
    becomes one :class:`~sweep3d.core.errors.PluginError` naming it, in the render worker too (an exit
    there would end the worker, not name the control); sweep3d's own controls' exceptions are
    bugs, raised as they are."""
    try:
        yield
    except PLUGIN_FAILURES as exc:
        if not is_user_plugin(control.type_name):
            raise
        raise plugin_failure(control_label(control), exc, f"failed in {method}", during=f"in {method}") from None


def wrap_periodic(value: float, period: float) -> float:
    """Wrap ``value`` into (-period/2, period/2], with -0.0 folded to 0.0."""
    half = period / 2.0
    if -half < value <= half:
        return value + 0.0  # already canonical: keep it bit-exact
    wrapped = math.fmod(value + half, period)
    if wrapped <= 0.0:
        wrapped += period
    result = wrapped - half
    # fmod is exact, but the shifts above can land a hair off for huge inputs: snap ties.
    if math.isclose(result, -half, rel_tol=0, abs_tol=1e-9):
        result = half
    return result + 0.0


def wrap_periodic_many(values: np.ndarray, period: float) -> np.ndarray:
    """:func:`wrap_periodic` of each value (float64), bit for bit: values already in range are
    folded with numpy, the few outside it go through the scalar function."""
    values = np.asarray(values).astype(np.float64)
    half = period / 2.0
    out = values + 0.0
    for i in np.flatnonzero(~((-half < values) & (values <= half))).tolist():
        out[i] = wrap_periodic(float(values[i]), period)
    return out
