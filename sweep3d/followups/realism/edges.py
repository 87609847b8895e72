"""Edge images of renders: the outline to lay over a live camera view while aligning a real scene.

A photograph is aligned to a render by matching outlines, not colours (a real room is never lit
as the simulation is), so the overlay is the render's strong edges, the object's silhouette and
its inner edges, in one bright colour on a transparent background (the 3DB paper's Section 5 app
offered the same toggle). Edges are found per colour channel (Canny), so an edge between two
colours of equal brightness still shows; weak texture and noise stay out (fixed thresholds, not
ones relative to the image: a flat image has no edges). Deterministic: the same pixels give the
same bytes.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

#: The edges' colour (opaque magenta): rare in real rooms, visible on light and dark scenes.
EDGE_RGB = (255, 0, 255)
#: Canny's hysteresis thresholds on the smoothed gradient of a channel in [0, 1]: an edge starts
#: where the gradient exceeds HIGH and continues while it exceeds LOW (chosen on quickstart
#: renders: outlines and printed seams kept, HDRI texture and shading mostly left out).
LOW, HIGH = 0.08, 0.2
#: The side of the render that Canny's smoothing (sigma 1 px) and one-pixel lines are tuned to;
#: larger renders are smoothed more and get thicker lines, so the outline looks the same.
BASE_SIDE = 224


def edge_mask(rgb: np.ndarray) -> np.ndarray:
    """Where ``rgb`` (H, W, 3) uint8 has a strong edge in any channel: (H, W) bool."""
    from skimage.feature import canny  # scikit-image: imported on use (a heavy import)

    _check(rgb)
    side = min(rgb.shape[:2])
    sigma = max(1.0, side / BASE_SIDE)
    channels = rgb.astype(np.float32) / np.float32(255.0)
    mask = np.zeros(rgb.shape[:2], dtype=bool)
    for c in range(3):
        mask |= canny(channels[..., c], sigma=sigma, low_threshold=LOW, high_threshold=HIGH, mode="nearest")
    radius = int(side // (2 * BASE_SIDE))  # 0 up to 447 px, then one more pixel per 448
    if radius:
        disk = np.hypot(*np.mgrid[-radius:radius + 1, -radius:radius + 1]) <= radius
        mask = ndimage.binary_dilation(mask, structure=disk)
    return mask


def edge_image(rgb: np.ndarray) -> np.ndarray:
    """A render's strong edges as an overlay: (H, W, 4) uint8 RGBA, :data:`EDGE_RGB` and opaque on
    an edge, transparent black (0, 0, 0, 0) elsewhere.

    Raises:
        ValueError: ``rgb`` is not an (H, W, 3) uint8 array.
    """
    mask = edge_mask(rgb)
    rgba = np.zeros((*mask.shape, 4), dtype=np.uint8)
    rgba[mask] = (*EDGE_RGB, 255)
    return rgba


def _check(rgb: np.ndarray) -> None:
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        got = f"{rgb.dtype} {rgb.shape}" if isinstance(rgb, np.ndarray) else type(rgb).__name__
        raise ValueError(f"edge_image needs an (H, W, 3) uint8 RGB array, got {got}")
    if min(rgb.shape[:2]) < 1:
        raise ValueError(f"edge_image needs a non-empty image, got shape {rgb.shape}")
