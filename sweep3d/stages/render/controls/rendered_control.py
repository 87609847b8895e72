"""The base class of rendered controls."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from sweep3d.core import Control, ControlParams, Registry
from sweep3d.stages.render.state import SceneState

if TYPE_CHECKING:
    from sweep3d.stages.render.cycles.scene_edit import SceneEdit


class RenderedControl(Control):
    """Changes the 3D scene before it is rendered, in one or both of two ways.

    ``apply`` edits the plain :class:`SceneState` (pose, camera, lights, materials, ...); it runs
    wherever the job is planned or rendered and needs no Blender, and the worker starts every job
    from a fresh state, so it needs no undo. ``edit`` runs in the render worker only, after the
    state is posed in Blender, and gets the live scene (:class:`~.scene_edit.SceneEdit`): it may
    add or change anything Blender can. Whatever it creates or changes is gone before the next
    job (see :mod:`sweep3d.stages.render.cycles.sandbox`); it need not clean up. ``order`` sorts
    application (object pose, then camera, then in-frame placement, which needs the final camera).
    """

    stage = "render"
    order: ClassVar[int] = 50
    #: What ``apply`` sets of the fields the planner's in-frame test reads (``state.FRAME_FIELDS``),
    #: as parameter → field, for an ``apply`` that copies parameters to fields; ``{}`` when it
    #: sets none of them. None (unknown): the planner applies the control job by job instead.
    frame_fields: ClassVar[dict[str, str] | None] = None

    def apply(self, state: SceneState, params: ControlParams) -> None:
        """Set this job's values on the plain scene state (default: nothing)."""

    def edit(self, scene: SceneEdit, params: ControlParams) -> None:
        """Change the live Blender scene for this job (default: nothing; see the class docstring)."""

    @property
    def edits_scene(self) -> bool:
        """Whether this control defines :meth:`edit` (its jobs then run in the worker's sandbox)."""
        return type(self).edit is not RenderedControl.edit


#: The rendered controls a spec may name (``[[controls]] type = ...``).
RENDERED_CONTROLS: Registry[type[RenderedControl]] = Registry("control")


def frame_fields(control: RenderedControl) -> dict[str, str] | None:
    """``control.frame_fields``, trusted only when the class that declares it also defines ``apply``
    (a subclass that overrides ``apply`` may move the object in other ways: None)."""
    mro = type(control).__mro__
    if type(control).apply is RenderedControl.apply:
        return {}  # it sets no field of the state (an edit-only control)
    declares = next((c for c in mro if "frame_fields" in c.__dict__), None)
    applies = next((c for c in mro if "apply" in c.__dict__), None)
    return control.frame_fields if declares is not None and declares is applies else None
