"""What a rendered control's ``edit`` gets, and how the worker runs it in a sandbox.

``edit(scene, params)`` receives a :class:`SceneEdit`: the live Blender scene of one job, posed
by the built-in state, with handles on the object, the camera and the empties that carry the
object. The worker takes a :func:`~.sandbox.snapshot` first and cleans up after the render
whatever the control did (:func:`render_edited`). Where the edit changed data the scene held, the
scene is rebuilt only once the job's reply has been made (:meth:`BlenderScene.rebuild_if_stale`):
rebuilding replaces the truth and UV passes' readers, and with them what they read of this render.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from sweep3d.core import PluginError, blamed, control_label, is_user_plugin
from sweep3d.stages.render.cycles.sandbox import clean_up, snapshot

if TYPE_CHECKING:
    from pydantic import BaseModel

    from sweep3d.stages.render.controls.rendered_control import RenderedControl
    from sweep3d.stages.render.cycles.scene import BlenderScene


@dataclass(frozen=True)
class SceneEdit:
    """The live scene of one job, for a control's ``edit``.

    Attributes:
        bpy: Blender's Python module.
        scene: the ``bpy.types.Scene`` that renders.
        objects: the object's mesh objects that render (its parts), as imported.
        pose: the empty that the pose controls move; in its frame the object fits a sphere of
            radius 1 at the origin, and a child of it moves with the object.
        source: the empty that holds the object in its file's own units (a child of ``pose``):
            parent geometry here to place it by the mesh's coordinates (centimetres for Sweet Home 3D).
        camera: the scene's camera object.
        object_name: the spec's name of the job's object.
        environment_name: the spec's name of the job's environment.
    """

    bpy: Any
    scene: Any
    objects: tuple[Any, ...]
    pose: Any
    source: Any
    camera: Any
    object_name: str = ""
    environment_name: str = ""

    def add(self, obj: Any, parent: Any = None, part_of_object: bool = False) -> Any:
        """Link a new object into the scene under ``parent`` (default: :attr:`pose`), keeping its
        transform as given in the parent's frame; ``part_of_object``: the truth passes count its
        pixels as the object's (a liquid in a mug), else it is scenery (it may hide the object).

        Returns:
            ``obj``, for chaining.
        """
        self.scene.collection.objects.link(obj)
        obj.parent = parent if parent is not None else self.pose
        obj.pass_index = 1 if part_of_object else 0
        return obj


#: Told the id of each control before its ``edit()``, and None after the job's last one.
OnEdit = Callable[[str | None], None]


class EditedRenderError(RuntimeError):
    """Blender failed to render the scene a user's control's ``edit()`` left: the job's error
    names the control (the message is the whole line)."""


def render_edited(scene: BlenderScene, edits: list[tuple[RenderedControl, BaseModel]],
                  object_name: str = "", environment_name: str = "",
                  on_edit: OnEdit | None = None) -> tuple[np.ndarray, tuple[str, ...]]:
    """Run each control's ``edit`` on the posed scene, render, and undo whatever they did.

    Args:
        on_edit: hears each control's id as its ``edit`` is called, and None once they all have
            returned: a worker tells its pool, which times an edit apart from the render and
            names a user's control if the worker dies in its ``edit``.

    Returns:
        The render (as :meth:`BlenderScene.render`) and what the edits changed of the data the
        scene held before (empty when they only added things; else the scene is marked stale, and
        the caller rebuilds it with :meth:`BlenderScene.rebuild_if_stale` once it has read the
        render's passes).

    Raises:
        PluginError: an ``edit`` raised, or left the scene without its camera; the scene is
            cleaned up all the same.
        EditedRenderError: Blender failed to render what a user's ``edit`` left.
    """
    bpy = scene.bpy
    bpy.context.view_layer.update()  # derived values (world matrices) as the render will leave them
    before = snapshot(bpy)
    try:
        context = SceneEdit(bpy, scene.scene, tuple(scene.meshes), scene.pose, scene.current.normaliser,
                            scene.camera, object_name, environment_name)
        for control, params in edits:
            _edit(control, params, context, on_edit)
        if on_edit is not None:
            on_edit(None)
        rgb = _render(scene, edits)
    finally:
        changed = clean_up(bpy, before).changed
        if changed:
            scene.stale = True  # not rebuilt yet: the passes of this render are still to be read
    return rgb, changed


def _edit(control: RenderedControl, params: BaseModel, context: SceneEdit, on_edit: OnEdit | None) -> None:
    """One control's ``edit``, announced (the pool times it, and names a user's control whose
    ``edit`` its worker dies in), and a user's that leaves no camera refused (every job would
    fail to render)."""
    user = is_user_plugin(control.type_name)
    if on_edit is not None:
        on_edit(control.id)
    with blamed(control, "edit()"):
        control.edit(context, params)
    problem = camera_problem(context.scene) if user else None
    if problem:
        raise PluginError(f"{control_label(control)} {problem} in edit(); an edit() may replace the camera "
                          "(set scene.scene.camera) but must leave one in the scene")


def camera_problem(scene: Any) -> str | None:
    """What is wrong with the scene's camera after an edit (None: it has one, in the scene)."""
    try:
        camera = scene.camera
        if camera is None:
            return "removed the scene's camera"
        if scene.objects.get(camera.name) is None:
            return "unlinked the scene's camera from the scene"
    except ReferenceError:  # the camera's object was freed under the scene
        return "removed the scene's camera"
    return None


def _render(scene: BlenderScene, edits: list[tuple[RenderedControl, BaseModel]]) -> np.ndarray:
    """The edited scene's render; a failure names the users' controls that edited it."""
    try:
        return scene.render()
    except Exception as exc:
        users = [control_label(c) for c, _ in edits if is_user_plugin(c.type_name)]
        if not users:
            raise
        raise EditedRenderError(f"{type(exc).__name__}: {' '.join(str(exc).split())} (rendering the scene the edit() "
                                f"of {', '.join(users)} left)") from exc
