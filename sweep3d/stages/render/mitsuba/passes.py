"""The truth passes (object mask, depth) of a Mitsuba render, with Cycles' meaning and blobs.

One ray through each pixel's centre (a stratified sampler without jitter, one sample) through
Mitsuba's ``aov`` integrator (ray distance, hit position, shape index) with a box filter, so each
pixel is one ray's answer and not a blend, as Cycles' index and depth passes are. The mask is the pixels whose first hit is one of the object's shapes
(the occluder hides it); depth is the distance along the camera axis to whatever is hit (``inf``
where nothing is). The visible fraction's denominator is found as ``truth_pass.TruthPass`` finds
it: the mask itself when nothing else is in the scene and the object lies inside the image,
else a second, surfaces-only render without the occluder over a frame enlarged around the same
axis with the same pixel pitch (coarser when large), windowed to the object's projected box.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from sweep3d.core import encode_depth, encode_mask, ground_truth
from sweep3d.stages.render.mitsuba import translate
from sweep3d.stages.render.mitsuba.scene import OBJECT
from sweep3d.stages.render.silhouette import MAX_SILHOUETTE_PIXELS, framed_count

if TYPE_CHECKING:
    from sweep3d.stages.render.mitsuba.scene import MitsubaScene

SURFACES = {"type": "aov", "aovs": "t:depth,p:position,i:shape_index"}


class MitsubaTruth:
    """Reads the truth passes of each job (``TruthPass``'s ``truth`` and ``blobs``)."""

    def __init__(self, scene: MitsubaScene, passes: tuple[str, ...]) -> None:
        self.passes = passes
        self.truth: dict[str, Any] | None = None
        self.blobs: dict[str, bytes] = {}

    def read(self, scene: MitsubaScene) -> None:
        """The passes of the job just rendered, and the unoccluded silhouette's pixels."""
        started = time.perf_counter()
        s = scene.settings
        size, crop = s.resolution, s.crop or s.resolution
        left = (size - crop) // 2
        hit, obj, z = surfaces(scene, size, 1.0, (left, left, crop, crop), scenery=True)
        self.blobs = {"mask": encode_mask(obj)}
        if "depth" in self.passes:
            self.blobs["depth"] = encode_depth(np.where(hit, z, np.inf).astype(np.float32))
        silhouette, framed, how = self._silhouette(scene, obj)
        self.truth = {**ground_truth(obj, silhouette, framed), "silhouette": how,
                      "truth_seconds": time.perf_counter() - started}

    def _silhouette(self, scene: MitsubaScene, mask: np.ndarray) -> tuple[float | None, float | None, str]:
        """As ``TruthPass._silhouette``: ("mask" | "render" | "coarse" | "unbounded")."""
        state, s, loaded = scene.state, scene.settings, scene.current
        size, crop = s.resolution, s.crop or s.resolution
        position, right, up, forward = state.camera_basis()
        m = translate.object_matrix(state, loaded.centre, loaded.radius)
        world = loaded.points @ m[:3, :3].T + m[:3, 3] - position
        x, y, depth = world @ right, world @ up, world @ forward
        if not np.all(depth > max(state.camera_distance() * 1e-4, 1e-6)):
            return None, None, "unbounded"
        pitch = state.focal_length / 36.0 * size
        px, py = size / 2 + x / depth * pitch, size / 2 - y / depth * pitch
        left = (size - crop) // 2
        inside = px.min() >= left + 1 and py.min() >= left + 1 and px.max() <= left + crop - 1 \
            and py.max() <= left + crop - 1
        if inside and state.occluder is None:
            count = float(np.count_nonzero(mask))
            return count, count, "mask"
        x0, y0 = math.floor(px.min()) - 1, math.floor(py.min()) - 1
        x1, y1 = math.ceil(px.max()) + 1, math.ceil(py.max()) + 1
        margin = max(0, -x0, -y0, x1 - size, y1 - size)
        big = size + 2 * margin
        x0, y0, x1, y1 = x0 + margin, y0 + margin, x1 + margin, y1 + margin
        scale = max(1.0, math.sqrt((x1 - x0) * (y1 - y0) / MAX_SILHOUETTE_PIXELS))
        side = max(1, int(round(big / scale)))
        scale = big / side
        cx0, cy0 = max(0, math.floor(x0 / scale)), max(0, math.floor(y0 / scale))
        cx1, cy1 = min(side, math.ceil(x1 / scale)), min(side, math.ceil(y1 / scale))
        _, silhouette, _ = surfaces(scene, side, big / size, (cx0, cy0, cx1 - cx0, cy1 - cy0), scenery=False)
        first = margin + left
        framed = framed_count(silhouette, (cx0, cy0), (first / scale, (first + crop) / scale))
        return (float(np.count_nonzero(silhouette)) * scale * scale, framed * scale * scale,
                "render" if scale == 1.0 else "coarse")


def surfaces(scene: MitsubaScene, size: int, widen: float, window: tuple[int, int, int, int],
             scenery: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One ray per pixel of ``window`` (x, y, width, height from the top left) of a ``size``²
    frame whose half-width's tangent is ``widen`` times the camera's: what is hit, what of it is
    the object's, and the depth along the camera axis (bool, bool, float (H, W) arrays)."""
    state = scene.state
    sensor = translate.camera(state, size, None, 0.5)
    half = math.atan(math.tan(math.radians(sensor["fov"]) / 2.0) * widen)
    sensor["fov"] = math.degrees(2.0 * half)
    x, y, w, h = window
    sensor["film"] = {**sensor["film"], "rfilter": {"type": "box"}, "crop_offset_x": x, "crop_offset_y": y,
                      "crop_width": w, "crop_height": h}
    sensor["sampler"] = {"type": "stratified", "sample_count": 1, "jitter": False}  # the pixel's centre, as Cycles
    mi = scene.mi
    if scenery and scene.loaded is not None:  # the job's own scene, seen by this sensor
        loaded = scene.loaded
        image = mi.render(loaded, sensor=mi.load_dict(scene.converted(sensor)), integrator=mi.load_dict(SURFACES),
                          spp=1, seed=scene.settings.seed)
    else:
        loaded = scene.load(scene.describe(SURFACES, sensor, scenery=scenery, lit=False))
        image = mi.render(loaded, spp=1, seed=scene.settings.seed)
    image = np.asarray(image, dtype=np.float64)
    # the scenery's numbers: a hit on anything else is the object's (the pieces of its instance
    # are numbered apart from the scene's shapes under llvm_ad_rgb: shape_numbers)
    scenery_numbers = [number for number, shape in zip(shape_numbers(mi, loaded), loaded.shapes(), strict=True)
                       if not shape.id().startswith(OBJECT)]
    index = np.rint(image[..., 4]).astype(np.int64)
    hit = (image[..., 0] > 0) & (index > 0)
    obj = hit & ~np.isin(index, scenery_numbers)
    position, _, _, forward = state.camera_basis()
    z = (image[..., 1:4] - position) @ forward
    return hit, obj, np.where(hit, z, np.inf)


def shape_numbers(mi, loaded) -> list[int]:
    """What the ``shape_index`` AOV gives for each of ``loaded.shapes()``: its place from 1 under
    ``scalar_rgb`` (an instance's pieces: the instance's), its number in Dr.Jit's registry (shared
    by every scene in the process) under ``llvm_ad_rgb`` (an instance's pieces: their own numbers)."""
    if mi.variant().startswith("scalar"):
        return list(range(1, len(loaded.shapes()) + 1))
    import drjit as dr

    return [int(n) for n in dr.reinterpret_array(mi.UInt32, loaded.shapes_dr())]
