"""The unoccluded silhouette's bounds, shared by every engine's truth passes: a silhouette render
is windowed to the object's projected box at the stored image's pixel pitch (coarser beyond
:data:`MAX_SILHOUETTE_PIXELS`), and :func:`framed_count` counts what the frame's edge leaves of it."""

from __future__ import annotations

import numpy as np

#: The most pixels a silhouette render's window has before its pitch is made coarser.
MAX_SILHOUETTE_PIXELS = 512 * 512


def framed_count(silhouette: np.ndarray, origin: tuple[int, int], image: tuple[float, float]) -> int:
    """Pixels of a bordered ``silhouette`` render (its top-left pixel at ``origin``, x and y from
    the top left of the enlarged frame) whose centres lie in the stored image, ``image`` = [lo, hi)
    on both axes in the same pixels: what the frame's edge leaves of the unoccluded object."""
    h, w = silhouette.shape
    lo, hi = image
    cols = np.arange(w) + origin[0] + 0.5
    rows = np.arange(h) + origin[1] + 0.5
    inside = ((rows >= lo) & (rows < hi))[:, None] & ((cols >= lo) & (cols < hi))[None, :]
    return int(np.count_nonzero(silhouette & inside))
