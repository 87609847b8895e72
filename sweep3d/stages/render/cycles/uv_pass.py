"""The UV pass, written only when a consumer asks for it (the report's part-visibility panel).

With persistent render data a pass switched on after the first render comes back all zeros, so
the pass is part of the worker's settings and set up before the scene renders anything. The
compositor writes the pass as three 16-bit greyscale PNGs (u, v and an object mask from the
object-index pass) next to the frame; Blender's Render Result holds no pixels headless.

The pass reads the ``sweep3d_parts`` UV map (see :mod:`sweep3d.core.uv_cells`), which is
made the mesh's render UV map; image textures that used the mesh's own UV map implicitly are
pointed at it explicitly first, so the RGB image does not change.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from sweep3d.core import UV_MAP, UserError, loop_uvs, part_counts
from sweep3d.stages.render.cycles.compositor import pass_outputs

CHANNELS = ("u", "v", "mask")


class UVPass:
    """Sets up the pass in ``scene`` and reads it back after each render."""

    def __init__(self, bpy, scene, scratch: Path) -> None:
        self.bpy = bpy
        self.folder = scratch / f"uv-{os.getpid()}"
        layer = scene.view_layers[0]
        layer.use_pass_uv = True
        layer.use_pass_object_index = True
        tree, layers, out = pass_outputs(scene, self.folder, CHANNELS, exr=False)
        split = tree.nodes.new("CompositorNodeSeparateColor")
        tree.links.new(layers.outputs["UV"], split.inputs[0])
        tree.links.new(split.outputs[0], out.inputs[0])
        tree.links.new(split.outputs[1], out.inputs[1])
        tree.links.new(layers.outputs["IndexOB"], out.inputs[2])
        self.frame = scene.frame_current

    def prepare(self, meshes: list[Any], frame_of) -> None:
        """Give each of ``meshes`` the parts UV map, computed in the object's normalised frame.

        Args:
            frame_of: maps a mesh object to the 4×4 matrix from its data to the normalised frame.
        """
        for obj in meshes:
            mesh = obj.data
            obj.pass_index = 1  # the mask: the object's pixels, not the ground or the occluder
            n = len(mesh.vertices)
            points = np.empty(n * 3, dtype=np.float64)
            mesh.vertices.foreach_get("co", points)
            m = np.asarray(frame_of(obj), dtype=np.float64)
            points = points.reshape(n, 3) @ m[:3, :3].T + m[:3, 3]
            loop_vertices = np.empty(len(mesh.loops), dtype=np.int64)
            mesh.loops.foreach_get("vertex_index", loop_vertices)
            starts = np.empty(len(mesh.polygons), dtype=np.int64)
            mesh.polygons.foreach_get("loop_start", starts)
            order = np.argsort(starts, kind="stable")
            uvs = loop_uvs(points, loop_vertices, starts[order])
            self._pin_textures(obj)
            layer = mesh.uv_layers.get(UV_MAP) or mesh.uv_layers.new(name=UV_MAP, do_init=False)
            if layer is None:
                raise UserError(f"mesh {obj.name!r} has {len(mesh.uv_layers)} UV maps, Blender's limit: the "
                                "part-visibility pass needs one more (remove one, or set [report] "
                                "part_visibility = false)")
            layer.data.foreach_set("uv", uvs.ravel())
            layer.active_render = True

    def _pin_textures(self, obj) -> None:
        """Point image textures that follow the render UV map at the mesh's own map by name."""
        own = next((layer.name for layer in obj.data.uv_layers if layer.active_render and layer.name != UV_MAP), None)
        if own is None:
            return
        for slot in obj.material_slots:
            material = slot.material
            if material is None or not material.use_nodes:
                continue
            tree = material.node_tree
            for node in list(tree.nodes):
                if node.bl_idname == "ShaderNodeTexImage" and not node.inputs["Vector"].is_linked:
                    uv = tree.nodes.new("ShaderNodeUVMap")
                    uv.uv_map = own
                    tree.links.new(uv.outputs["UV"], node.inputs["Vector"])
                elif node.bl_idname == "ShaderNodeNormalMap" and not node.uv_map:
                    node.uv_map = own

    def read(self) -> dict[str, Any]:
        """Pixels per visible part in the frame just rendered (see :func:`part_counts`)."""
        from PIL import Image

        planes = []
        for name in CHANNELS:
            path = self.folder / f"{name}_{self.frame:04d}.png"
            with Image.open(path) as img:
                planes.append(np.asarray(img, dtype=np.float64) / 65535.0)
            path.unlink()
        u, v, mask = planes
        return part_counts(u, v, mask > 0.5)
