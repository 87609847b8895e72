"""Blender's copy of a job's lights (point, sun, area), kept between jobs.

Light objects are rebuilt only when the kinds of lights change; otherwise their values and
placement are written where they differ, so a camera move that carries a camera-relative light
along only moves it.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from sweep3d.stages.render.cycles._rna import assign, same
from sweep3d.stages.render.lights import AreaLight, SunLight
from sweep3d.stages.render.state import PointLight, SceneState

Light = PointLight | SunLight | AreaLight


def blender_light(light: Light, state: SceneState) -> tuple[str, dict[str, Any], np.ndarray]:
    """The bpy light type, the light data's values and the object's 4×4 matrix for ``light``."""
    if isinstance(light, PointLight):
        matrix = np.eye(4)
        matrix[:3, 3] = light.position()
        return "POINT", {"energy": light.watts, "color": light.rgb, "shadow_soft_size": light.radius}, matrix
    if isinstance(light, SunLight):
        values = {"energy": light.strength, "color": light.rgb, "angle": math.radians(light.angle)}
        return "SUN", values, light.matrix(state)
    shape = {"square": "SQUARE", "disk": "DISK"}[light.shape]
    values = {"energy": light.watts, "color": light.rgb, "shape": shape, "size": light.size, "normalize": True}
    return "AREA", values, light.matrix(state)


class Lamps:
    """The scene's light objects, one per light of the current job."""

    def __init__(self, bpy, scene) -> None:
        self.bpy, self.scene = bpy, scene
        self.objects: list[Any] = []

    def sync(self, lights: Sequence[Light], state: SceneState) -> None:
        """Make the scene's lights ``lights``, placed for ``state``'s camera and object."""
        wanted = [blender_light(light, state) for light in lights]
        if [kind for kind, _, _ in wanted] != [obj.data.type for obj in self.objects]:
            self._rebuild([kind for kind, _, _ in wanted])
        from mathutils import Matrix  # noqa: PLC0415  (ships with bpy)

        for obj, (_, values, matrix) in zip(self.objects, wanted):
            for name, value in values.items():
                assign(obj.data, name, value)
            if not same([list(row) for row in obj.matrix_world], matrix.tolist()):
                obj.matrix_world = Matrix(matrix.tolist())

    def _rebuild(self, kinds: list[str]) -> None:
        for obj in self.objects:
            data = obj.data
            self.bpy.data.objects.remove(obj, do_unlink=True)
            self.bpy.data.lights.remove(data)
        self.objects = []
        for i, kind in enumerate(kinds):
            data = self.bpy.data.lights.new(f"sweep3d_light_{i}", kind)
            obj = self.bpy.data.objects.new(f"sweep3d_light_{i}", data)
            self.scene.collection.objects.link(obj)
            self.objects.append(obj)
