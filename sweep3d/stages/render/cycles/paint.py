"""Paint an object with one colour per part and render it from a few sides.

The part-visibility panel shows accuracy "as a coloured render of the object" (the paper's
Figure 8): each part of the surface (see :mod:`sweep3d.core.uv_cells`) takes the colour of the accuracy
of the images that show it. The paint is an image texture of one texel per part on the parts UV
map, sampled without interpolation, lit by a plain white world so the colours read true.

:func:`paint_objects` runs Blender in a child process (:mod:`.child`; the report's process never imports bpy).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from sweep3d.core import AZIMUTH_PARTS, ELEVATION_PARTS, PARTS, UV_MAP
from sweep3d.stages.render.child import call_in_child
from sweep3d.stages.render.worker_protocol import Look

#: (label, camera azimuth, camera elevation): the sides shown, as the camera control names them.
SIDES = (("front", 0.0, 15.0), ("right", 90.0, 15.0), ("back", 180.0, 15.0), ("left", 270.0, 15.0),
         ("top", 0.0, 80.0), ("bottom", 0.0, -80.0))
BACKGROUND = (1.0, 1.0, 1.0)


def paint_objects(items: list[tuple[str, np.ndarray]], resolution: int = 160, samples: int = 16,
                  looks: list[Look | None] | None = None) -> list[list[bytes]]:
    """PNG renders of each ``(mesh, colours)`` (colours: PARTS × 3, sRGB in [0, 1]), one per side.

    Runs Blender once, in a fresh child process, for all the items. ``looks`` (one per item)
    paint only an object's ``parts``, as it was rendered.
    """
    looks = looks or [None] * len(items)
    items = [(mesh, np.asarray(colours, dtype=np.float32).reshape(PARTS, 3), look)
             for (mesh, colours), look in zip(items, looks)]
    if not items:
        return []
    return call_in_child(_paint_in_this_process, items, resolution, samples)  # no orphan if the report is killed


def _paint_in_this_process(items: list[tuple[str, np.ndarray, Look | None]], resolution: int,
                           samples: int) -> list[list[bytes]]:
    os.dup2(os.open(os.devnull, os.O_WRONLY), 1)  # Blender prints progress straight to fd 1
    from sweep3d.core import encode_png
    from sweep3d.stages.render.cycles.scene import BlenderScene
    from sweep3d.stages.render.state import SceneState
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderSettings

    # the UV pass builds the parts UV map the paint is laid on
    settings = RenderSettings(resolution=resolution, samples=samples, denoise=True, passes=("uv",))
    out = []
    with tempfile.TemporaryDirectory(prefix="sweep3d-paint-") as scratch:
        scene = BlenderScene(settings, Path(scratch))
        for mesh, colours, look in items:
            scene.prepare(mesh, EnvironmentRef(color=BACKGROUND), look)
            material = _paint_material(scene.bpy, colours)
            images = []
            for _, azimuth, elevation in SIDES:
                scene.pose_scene(SceneState(azimuth=azimuth, elevation=elevation, zoom=0.95))
                for obj in scene.meshes:
                    if not obj.material_slots:
                        obj.data.materials.append(material)
                    for slot in obj.material_slots:
                        slot.material = material
                images.append(encode_png(scene.render()))
            out.append(images)
    return out


def _paint_material(bpy, colours: np.ndarray):
    """A diffuse material whose colour is the part's texel (two turns of ``u``: see core/uv_cells.py)."""
    texels = np.ones((ELEVATION_PARTS, 2 * AZIMUTH_PARTS, 4), dtype=np.float32)
    grid = colours.reshape(ELEVATION_PARTS, AZIMUTH_PARTS, 3)
    texels[:, :AZIMUTH_PARTS, :3] = texels[:, AZIMUTH_PARTS:, :3] = grid
    image = bpy.data.images.new("sweep3d_paint", 2 * AZIMUTH_PARTS, ELEVATION_PARTS, alpha=True)
    image.colorspace_settings.name = "sRGB"
    image.pixels.foreach_set(texels.ravel())  # rows from the bottom: row 0 = lowest band
    image.pack()
    material = bpy.data.materials.new("sweep3d_paint")
    material.use_nodes = True
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    uv = nodes.new("ShaderNodeUVMap")
    uv.uv_map = UV_MAP
    texture = nodes.new("ShaderNodeTexImage")
    texture.image = image
    texture.interpolation = "Closest"
    texture.extension = "EXTEND"  # u stays below 0.75; v = 1 (the top pole) must not wrap
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(uv.outputs["UV"], texture.inputs["Vector"])
    links.new(texture.outputs["Color"], diffuse.inputs["Color"])
    links.new(diffuse.outputs["BSDF"], out.inputs["Surface"])
    return material
