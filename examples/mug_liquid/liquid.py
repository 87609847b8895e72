"""The 3DB paper's mug-liquid study as one sweep3d control: fill a mug with a water:milk:coffee mixture.

``mixture`` is "water:milk:coffee" in parts (e.g. "2:0:1"; "" = the empty mug) and ``fill`` how full
the mug is. The control finds the mug's inside from its mesh (the rim's inner edge and the floor),
adds a liquid cylinder there with a Principled BSDF blended from the three liquids, and leaves the
rest to sweep3d: the worker removes the liquid after each job.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from sweep3d.plugins import ControlParams, RenderedControl

#: Each liquid's look (linear RGB base colour, roughness, transmission), blended by the mixture's parts.
LIQUIDS = {
    "water": ((0.80, 0.90, 1.00), 0.02, 1.0),
    "milk": ((0.92, 0.91, 0.86), 0.25, 0.0),
    "coffee": ((0.06, 0.025, 0.008), 0.05, 0.0),
}


class Liquid(RenderedControl):
    """A liquid in the mug: ``mixture`` = "water:milk:coffee" parts ("" = empty), ``fill`` 0..1 of its depth."""

    class Params(ControlParams):
        mixture: str = Field("", pattern=r"^(\d+(\.\d+)?:\d+(\.\d+)?:\d+(\.\d+)?)?$")
        fill: float = Field(0.8, gt=0.0, le=0.98)

    def edit(self, scene, params) -> None:
        parts = np.array([float(p) for p in params.mixture.split(":")]) if params.mixture else np.zeros(3)
        if parts.sum() <= 0:
            return  # the empty mug
        share = parts / parts.sum()
        centre, radius, floor, rim = _inside(scene)
        level = floor + params.fill * (rim - floor)
        liquid = _cylinder(scene.bpy, radius * 0.985, floor, level)
        liquid.data.materials.append(_material(scene.bpy, share))
        liquid.location = (centre[0], centre[1], 0.0)
        scene.add(liquid, parent=scene.source, part_of_object=True)


def _vertices(scene) -> np.ndarray:
    """The mug's vertices in the frame of ``scene.source`` (its file's units, z up), shape (n, 3)."""
    to_source = np.array(scene.source.matrix_world.inverted())
    chunks = []
    for obj in scene.objects:
        n = len(obj.data.vertices)
        local = np.empty(n * 3)
        obj.data.vertices.foreach_get("co", local)
        matrix = to_source @ np.array(obj.matrix_world)
        chunks.append(local.reshape(n, 3) @ matrix[:3, :3].T + matrix[:3, 3])
    return np.concatenate(chunks)


def _inside(scene) -> tuple[np.ndarray, float, float, float]:
    """The mug's axis (x, y), inner radius at the rim, the inside floor's height and the rim's."""
    points = _vertices(scene)
    z = points[:, 2]
    height = z.max() - z.min()
    rim = points[z > z.max() - 0.03 * height]  # the rim ring: the handle does not reach it
    centre = (rim[:, :2].min(axis=0) + rim[:, :2].max(axis=0)) / 2
    radius = float(np.hypot(*(rim[:, :2] - centre).T).min())
    near_axis = np.hypot(*(points[:, :2] - centre).T) < 0.6 * radius
    floor = float(z[near_axis & (z < z.max() - 0.5 * height)].max())
    return centre, radius, floor, float(z.max())


def _cylinder(bpy, radius: float, bottom: float, top: float):
    import bmesh

    mesh = bpy.data.meshes.new("liquid")
    shape = bmesh.new()
    bmesh.ops.create_cone(shape, cap_ends=True, segments=64, radius1=radius, radius2=radius, depth=top - bottom)
    bmesh.ops.translate(shape, vec=(0.0, 0.0, (top + bottom) / 2), verts=shape.verts)
    shape.to_mesh(mesh)
    shape.free()
    for polygon in mesh.polygons:
        polygon.use_smooth = True
    return bpy.data.objects.new("liquid", mesh)


def _material(bpy, share: np.ndarray):
    looks = list(LIQUIDS.values())
    # colours mix as absorptions do (a weighted geometric mean): a third of coffee browns the milk
    colour = np.exp(sum(w * np.log(np.array(c)) for w, (c, _, _) in zip(share, looks)))
    material = bpy.data.materials.new("liquid")
    material.use_nodes = True
    bsdf = material.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    bsdf.inputs["Roughness"].default_value = float(sum(w * r for w, (_, r, _) in zip(share, looks)))
    bsdf.inputs["Transmission Weight"].default_value = float(sum(w * t for w, (_, _, t) in zip(share, looks)))
    bsdf.inputs["IOR"].default_value = 1.34
    return material
