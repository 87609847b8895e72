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
    #: What ``apply`` sets of the fields the planner's in-frame test reads (``state.FRAME_FIELDS``),
    #: as parameter → field, for an ``apply`` that copies parameters to fields; ``{}`` when it
    #: sets none of them. None (unknown): the planner applies the control job by job instead.
    frame_fields: ClassVar[dict[str, str] | None] = None

    def apply(self, state: SceneState, params: ControlParams) -> None:
        raise NotImplementedError


#: The rendered controls a spec may name (``[[controls]] type = ...``).
RENDERED_CONTROLS: Registry[type[RenderedControl]] = Registry("control")


def frame_fields(control: RenderedControl) -> dict[str, str] | None:
    """``control.frame_fields``, trusted only when the class that declares it also defines ``apply``
    (a subclass that overrides ``apply`` may move the object in other ways: None)."""
    mro = type(control).__mro__
    declares = next((c for c in mro if "frame_fields" in c.__dict__), None)
    applies = next((c for c in mro if "apply" in c.__dict__), None)
    return control.frame_fields if declares is not None and declares is applies else None
