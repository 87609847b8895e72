"""What a rendered control's ``edit`` gets, and how the worker runs it in a sandbox.

``edit(scene, params)`` receives a :class:`SceneEdit`: the live Blender scene of one job, posed
by the built-in state, with handles on the object, the camera and the empties that carry the
object. The worker takes a :func:`~.sandbox.snapshot` first and cleans up after the render
whatever the control did (:func:`render_edited`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from sweep3d.controls import blamed
from sweep3d.stages.render.sandbox import clean_up, snapshot

if TYPE_CHECKING:
    from pydantic import BaseModel

    from sweep3d.stages.render.controls.base import RenderedControl
    from sweep3d.stages.render.scene import BlenderScene


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


def render_edited(scene: BlenderScene, edits: list[tuple[RenderedControl, BaseModel]],
                  object_name: str = "", environment_name: str = "",
                  on_edit: Callable[[str | None], None] | None = None) -> tuple[np.ndarray, tuple[str, ...]]:
    """Run each control's ``edit`` on the posed scene, render, and undo whatever they did.

    ``on_edit`` hears each control's id as its ``edit`` is called, and None once they all have
    returned: a worker tells its pool, which times an edit apart from the render.

    Returns:
        The render (as :meth:`BlenderScene.render`) and what the edits changed of the data the
        scene held before (empty when they only added things; else the scene was rebuilt).

    Raises:
        PluginError: an ``edit`` raised; the scene is cleaned up all the same.
    """
    bpy = scene.bpy
    bpy.context.view_layer.update()  # derived values (world matrices) as the render will leave them
    before = snapshot(bpy)
    try:
        context = SceneEdit(bpy, scene.scene, tuple(scene.meshes), scene.pose, scene.current.normaliser,
                            scene.camera, object_name, environment_name)
        for control, params in edits:
            if on_edit is not None:
                on_edit(control.id)
            with blamed(control, "edit()"):
                control.edit(context, params)
        if on_edit is not None:
            on_edit(None)
        rgb = scene.render()
    finally:
        changed = clean_up(bpy, before).changed
        if changed:
            scene.reset()
    return rgb, changed
