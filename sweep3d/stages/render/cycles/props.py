"""Objects a job adds around the subject: an occluding plate and a shadow-catching ground (lights:
:mod:`sweep3d.stages.render.cycles.lamps`). Each is moved, not rebuilt, when its part of the state changes."""

from __future__ import annotations

from typing import Any

import numpy as np

from sweep3d.stages.render.cycles._rna import assign
from sweep3d.stages.render.state import OCCLUDER_DEPTH, SceneState


class Props:
    def __init__(self, bpy, scene) -> None:
        self.bpy, self.scene = bpy, scene
        self.occluder = self._plate("sweep3d_occluder", (0.5, 0.5, 0.5))
        self.ground = self._plate("sweep3d_ground", (0.8, 0.8, 0.8))
        self.ground.is_shadow_catcher = True

    def _plate(self, name: str, rgb) -> Any:
        bpy = self.bpy
        mesh = bpy.data.meshes.new(name)
        mesh.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
        material = bpy.data.materials.new(name)
        material.use_nodes = True
        material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*rgb, 1.0)
        mesh.materials.append(material)
        obj = bpy.data.objects.new(name, mesh)
        self.scene.collection.objects.link(obj)
        obj.hide_render = True
        return obj

    def sync_occluder(self, state: SceneState) -> None:
        """Place a grey plate, facing the camera, over ``coverage`` of the object's projected disc."""
        occ = state.occluder
        assign(self.occluder, "hide_render", occ is None)
        if occ is None:
            return
        position, right, up, forward = state.camera_basis()
        centre = state.object_location()
        depth = float(np.dot(centre - position, forward))
        k = OCCLUDER_DEPTH
        radius = state.scale * k  # the object's bounding disc, scaled to the plate's depth
        theta = np.radians(occ.direction)
        direction = np.cos(theta) * right + np.sin(theta) * up
        half = 1.5 * radius
        inner_edge = radius * (1.0 - 2.0 * occ.coverage)
        axis_point = position + forward * depth * k + (centre - position - forward * depth) * k
        plate_centre = axis_point + direction * (inner_edge + half)
        from mathutils import Matrix  # noqa: PLC0415

        rotation = Matrix([list(right), list(up), list(-forward)]).transposed().to_4x4()
        self.occluder.matrix_world = Matrix.Translation(plate_centre) @ rotation @ Matrix.Diagonal((half, half, 1, 1))
        bsdf = self.occluder.data.materials[0].node_tree.nodes["Principled BSDF"]
        assign(bsdf.inputs["Base Color"], "default_value", (occ.grey, occ.grey, occ.grey, 1.0))

    def sync_ground(self, state: SceneState, lowest_z: float | None) -> None:
        """A large shadow catcher under the object's lowest point (when pinned to the ground)."""
        assign(self.ground, "hide_render", not state.pin_to_ground or lowest_z is None)
        if not self.ground.hide_render:
            size = 50.0 * max(state.scale, 1.0)
            self.ground.location = (0.0, 0.0, lowest_z)
            self.ground.scale = (size, size, 1.0)
