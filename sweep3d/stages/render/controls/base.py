"""The base class of rendered controls."""

from __future__ import annotations

from typing import ClassVar

from sweep3d.controls import Control, ControlParams
from sweep3d.registry import Registry
from sweep3d.stages.render.state import SceneState


class RenderedControl(Control):
    """Changes the 3D scene before it is rendered.

    ``apply`` edits the plain :class:`SceneState`; the worker resets the state for every job,
    so controls that only set state need no undo. ``order`` sorts application (object pose,
    then camera, then in-frame placement, which needs the final camera).
    """

    stage = "render"
    order: ClassVar[int] = 50

    def apply(self, state: SceneState, params: ControlParams) -> None:
        raise NotImplementedError


#: The rendered controls a spec may name (``[[controls]] type = ...``).
RENDERED_CONTROLS: Registry[type[RenderedControl]] = Registry("control")
