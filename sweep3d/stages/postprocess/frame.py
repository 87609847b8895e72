"""What a depth-aware post control reads beside the image: the render's passes and its camera.

The postprocess stage builds one :class:`RenderFrame` per job for the controls that declare
``passes`` (see :class:`~sweep3d.stages.postprocess.controls.post_control.PostControl`). Its numbers are
functions of the render key (the camera comes from the job's rendered controls and the frame's
size), so an image key made of the render key and the post controls' values stays correct.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from sweep3d.stages.render import SceneState


@dataclass(frozen=True)
class RenderFrame:
    """The passes of one render and the pinhole camera that made it.

    Attributes:
        depth: float32 (H, W), distance along the camera's axis (Cycles' Z pass) in object radii
            (Blender metres), ``inf`` where no surface was hit; None when not asked for.
        mask: bool (H, W), the object's visible pixels; None when not asked for.
        focal_length: the camera's focal length in mm (on the 36 mm sensor).
        focal_px: the same in pixels of the stored image.
        centre: where the optical axis meets the stored image, (x, y) in pixels from its top-left
            corner (pixel centres at i + 0.5): the middle, or half a pixel off it for an odd crop.
        subject_distance: from the camera to the object's centre, in object radii (where the
            ``camera`` control focuses).
    """

    depth: np.ndarray | None
    mask: np.ndarray | None
    focal_length: float
    focal_px: float
    centre: tuple[float, float]
    subject_distance: float

    def ray_factor(self, shape: tuple[int, int]) -> np.ndarray:
        """Per pixel, the length of its ray per unit of depth along the axis: sqrt(1 + (x² + y²) / f²)
        for the pixel centre's offset (x, y) from :attr:`centre` (float64, ``shape``)."""
        h, w = shape
        x = (np.arange(w) + 0.5 - self.centre[0]) / self.focal_px
        y = (np.arange(h) + 0.5 - self.centre[1]) / self.focal_px
        return np.sqrt(1.0 + y[:, None] ** 2 + x[None, :] ** 2)

    def ray_distance(self) -> np.ndarray:
        """Distance from the camera to the surface seen by each pixel's centre, float64 (H, W):
        ``inf`` where no surface was hit (a non-finite or non-positive depth counts as none)."""
        if self.depth is None:
            raise ValueError("this frame carries no depth pass")
        depth = np.asarray(self.depth, dtype=np.float64)
        hit = np.isfinite(depth) & (depth > 0)
        return np.where(hit, np.where(hit, depth, 1.0) * self.ray_factor(depth.shape), np.inf)


def frame_from_state(state: SceneState, size: int, crop: int | None, depth: np.ndarray | None,
                     mask: np.ndarray | None) -> RenderFrame:
    """The frame of a render of ``state`` on a ``size``-pixel square frame whose centre ``crop``
    (None: all of it) is stored, as ``stages/render/cycles/scene.py`` sets Blender's camera up."""
    from sweep3d.stages.render import SENSOR_WIDTH_MM

    left = (size - (crop or size)) // 2  # where the stored crop starts, from the top and left
    position, *_ = state.camera_basis()
    return RenderFrame(depth=depth, mask=mask, focal_length=state.focal_length, focal_px=size * state.focal_length / SENSOR_WIDTH_MM,
                       centre=(size / 2 - left, size / 2 - left),
                       subject_distance=float(np.linalg.norm(state.object_location() - position)))
