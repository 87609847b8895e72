"""The truth passes (object mask, depth), written only when a consumer asks for them.

Like the UV pass, the passes are part of the worker's settings (with persistent render data a
pass switched on after the first render comes back empty) and are written by a compositor File
Output node next to the frame: here as 32-bit float single-channel EXRs, read back through
``bpy.data.images`` (Blender's Render Result holds no pixels headless). They leave the RGB image
alone. The object's meshes carry ``pass_index = 1`` (set when loaded), so the object index pass
is the object's *visible* pixels: the occluder and the ground are index 0. Index passes are not
anti-aliased: a pixel is the object's or not.

The visible fraction's denominator is the object's silhouette with no occluder and an infinite
frame. An occluder is any shown surface that is not the object's (:func:`scenery`): the plate,
the ground, and whatever a control's ``edit`` added without ``part_of_object`` (index 0 like the
plate). When nothing of the scenery is shown and the object's projected points lie inside the
stored image, the silhouette is the mask itself (no extra render). Otherwise a second,
index-only render (1 sample, no denoiser, the scenery hidden) is made over a frame enlarged
around the same camera axis with the same pixel pitch, restricted by a render border to the
object's projected box; a box over :data:`MAX_SILHOUETTE_PIXELS` is rendered at a coarser pitch
and its count scaled back. The silhouette's pixels inside the stored image are counted too
(``framed_pixels``): no visible pixel with some of them is an object wholly occluded, with none
an object the frame's edge cut off.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from sweep3d.core import encode_depth, encode_mask, ground_truth
from sweep3d.stages.render.cycles.compositor import pass_outputs
from sweep3d.stages.render.silhouette import MAX_SILHOUETTE_PIXELS, framed_count

SLOTS = ("index", "depth")
#: Pixels of the enlarged silhouette render above which it is rendered at a coarser pitch.
NO_SURFACE = 1e9  # Cycles writes 1e10 in the depth pass where a ray hits nothing
#: Object types that show no surface of their own (an empty that instances a collection does).
NO_SURFACE_TYPES = frozenset({"CAMERA", "LIGHT", "LIGHT_PROBE", "LIGHTPROBE", "SPEAKER", "ARMATURE", "LATTICE",
                              "EMPTY"})


def shows_surface(obj: Any) -> bool:
    """Whether ``obj`` renders a surface that can cover pixels (a light or a plain empty does not)."""
    if obj.type == "EMPTY":
        return obj.instance_type == "COLLECTION" and obj.instance_collection is not None
    return obj.type not in NO_SURFACE_TYPES


def scenery(scene: Any) -> list[Any]:
    """The shown surfaces that are not the object's (``pass_index`` 0): the occluder plate, the
    ground and whatever a control's ``edit`` added without ``part_of_object``. The silhouette is
    taken without them, so anything that may hide the object counts as an occluder."""
    return [o for o in scene.objects if not o.hide_render and o.pass_index != 1 and shows_surface(o)]


def object_points(blender_scene: Any) -> np.ndarray:
    """World points whose projection bounds the object's silhouette: its meshes' vertices, and the
    bounding-box corners of what an ``edit`` added as ``part_of_object`` (a liquid may reach out)."""
    meshes = list(blender_scene.meshes)
    points = [blender_scene._world_vertices(meshes)]
    for obj in blender_scene.scene.objects:
        if obj.pass_index == 1 and not obj.hide_render and shows_surface(obj) and obj not in meshes:
            m = np.array(obj.matrix_world)
            points.append(np.array([tuple(c) for c in obj.bound_box], dtype=np.float64) @ m[:3, :3].T + m[:3, 3])
    return np.concatenate(points)


class TruthPass:
    """Sets up the passes in ``scene`` and reads them back after each render.

    Args:
        passes: the truth passes to keep ("mask", "depth"); the mask is always read (the
            ground-truth numbers come from it).
    """

    def __init__(self, bpy, scene, scratch: Path, passes: tuple[str, ...]) -> None:
        self.bpy = bpy
        self.scene = scene
        self.passes = passes
        self.folder = scratch / f"truth-{os.getpid()}"
        layer = scene.view_layers[0]
        layer.use_pass_object_index = True
        layer.use_pass_z = True
        tree, layers, out = pass_outputs(scene, self.folder, SLOTS, exr=True)
        tree.links.new(layers.outputs["IndexOB"], out.inputs[0])
        tree.links.new(layers.outputs["Depth"], out.inputs[1])
        self.frame = scene.frame_current
        self.truth: dict[str, Any] | None = None  # the latest render's numbers
        self.blobs: dict[str, bytes] = {}  # ... and its blobs by pass

    def _read(self, name: str) -> np.ndarray:
        """One slot of the latest render as a float32 (H, W) array, top row first."""
        path = self.folder / f"{name}_{self.frame:04d}.exr"
        image = self.bpy.data.images.load(str(path), check_existing=False)
        try:
            image.colorspace_settings.is_data = True
            w, h = image.size
            pixels = np.empty(w * h * image.channels, dtype=np.float32)
            image.pixels.foreach_get(pixels)
        finally:
            self.bpy.data.images.remove(image)
        path.unlink()
        return pixels.reshape(h, w, -1)[::-1, :, 0].copy()

    def read(self, blender_scene) -> None:
        """Read the passes of the render just made, then count the unoccluded silhouette."""
        started = time.perf_counter()
        mask = self._read("index") > 0.5
        depth = self._read("depth")
        self.blobs = {"mask": encode_mask(mask)}
        if "depth" in self.passes:
            self.blobs["depth"] = encode_depth(np.where(depth < NO_SURFACE, depth, np.inf))
        silhouette, framed, how = self._silhouette(blender_scene, mask)
        self.truth = {**ground_truth(mask, silhouette, framed), "silhouette": how,
                      "truth_seconds": time.perf_counter() - started}

    # -- the visible fraction's denominator ------------------------------------------------------
    def _silhouette(self, blender_scene, mask: np.ndarray) -> tuple[float | None, float | None, str]:
        """Pixels the object would cover with no occluder in an infinite frame, those of them in
        the stored image, and how they were found: "mask" (the mask is the whole silhouette),
        "render" (a second render at the image's pitch), "coarse" (at a coarser one), "unbounded"
        (None, None: the object reaches behind the camera)."""
        settings = blender_scene.settings
        size, crop = settings.resolution, settings.crop or settings.resolution
        self.bpy.context.view_layer.update()
        camera = blender_scene.camera
        inverse = np.array(camera.matrix_world.inverted())
        local = object_points(blender_scene) @ inverse[:3, :3].T + inverse[:3, 3]
        depth = -local[:, 2]
        if not np.all(depth > camera.data.clip_start):
            return None, None, "unbounded"
        pitch = camera.data.lens / camera.data.sensor_width * size  # pixels per unit of x / depth
        x = size / 2 + local[:, 0] / depth * pitch
        y = size / 2 - local[:, 1] / depth * pitch  # from the top
        left = (size - crop) // 2
        hidden = scenery(self.scene)
        inside = (x.min() >= left + 1 and y.min() >= left + 1 and x.max() <= left + crop - 1
                  and y.max() <= left + crop - 1)
        if inside and not hidden:
            count = float(np.count_nonzero(mask))
            return count, count, "mask"
        return self._render_silhouette(blender_scene, hidden, (x.min(), y.min(), x.max(), y.max()))

    def _render_silhouette(self, blender_scene, hidden: list[Any],
                           bounds: tuple[float, ...]) -> tuple[float, float, str]:
        """The silhouette render with ``hidden`` (the scenery) out of it: its pixel count, those in
        the stored image, and "render" or "coarse"."""
        render, cycles = self.scene.render, self.scene.cycles
        camera = blender_scene.camera.data
        settings = blender_scene.settings
        size, crop = settings.resolution, settings.crop or settings.resolution
        x0, y0, x1, y1 = (math.floor(bounds[0]) - 1, math.floor(bounds[1]) - 1,
                          math.ceil(bounds[2]) + 1, math.ceil(bounds[3]) + 1)
        margin = max(0, -x0, -y0, x1 - size, y1 - size)
        big = size + 2 * margin  # the frame enlarged around the same axis, same pixel pitch
        x0, y0, x1, y1 = x0 + margin, y0 + margin, x1 + margin, y1 + margin
        scale = max(1.0, math.sqrt((x1 - x0) * (y1 - y0) / MAX_SILHOUETTE_PIXELS))
        side = max(1, int(round(big / scale)))
        scale = big / side
        saved = {"resolution": (render.resolution_x, render.resolution_y), "sensor": camera.sensor_width,
                 "border": (render.use_border, render.use_crop_to_border, render.border_min_x, render.border_max_x,
                            render.border_min_y, render.border_max_y),
                 "sampling": (cycles.samples, cycles.use_denoising, cycles.use_adaptive_sampling)}
        try:
            for obj in hidden:
                obj.hide_render = True
            camera.sensor_width = saved["sensor"] * big / size
            render.resolution_x = render.resolution_y = side
            render.use_border = render.use_crop_to_border = True
            render.border_min_x, render.border_max_x = (x0 / scale + 0.25) / side, (x1 / scale + 0.25) / side
            render.border_min_y = max(0.0, (side - y1 / scale + 0.25) / side)
            render.border_max_y = min(1.0, (side - y0 / scale + 0.25) / side)
            cycles.samples, cycles.use_denoising, cycles.use_adaptive_sampling = 1, False, False
            self.bpy.ops.render.render(write_still=False)
            silhouette = self._read("index") > 0.5
            self._discard("depth")
            # Blender truncates border × side to the first pixel column and row (from the bottom)
            origin = (int(render.border_min_x * side), side - int(render.border_min_y * side) - silhouette.shape[0])
        finally:
            for obj in hidden:
                obj.hide_render = False
            camera.sensor_width = saved["sensor"]
            render.resolution_x, render.resolution_y = saved["resolution"]
            (render.use_border, render.use_crop_to_border, render.border_min_x, render.border_max_x,
             render.border_min_y, render.border_max_y) = saved["border"]
            cycles.samples, cycles.use_denoising, cycles.use_adaptive_sampling = saved["sampling"]
        left = margin + (size - crop) // 2  # the stored image's first column and row, from the top left
        image = (left / scale, (left + crop) / scale)
        framed = framed_count(silhouette, origin, image)
        return (float(np.count_nonzero(silhouette)) * scale * scale, framed * scale * scale,
                "render" if scale == 1.0 else "coarse")

    def _discard(self, name: str) -> None:
        (self.folder / f"{name}_{self.frame:04d}.exr").unlink(missing_ok=True)
