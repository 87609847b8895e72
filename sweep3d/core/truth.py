"""Ground truth from extra render passes: the object's mask and depth, its box and visibility (no bpy here).

Passes are rendered only when something declared needs them (see ``sweep3d.driver.passes``):

``mask``
    The object's *visible* pixels in the stored image (occluders excluded), from Cycles' object
    index pass (not anti-aliased: each pixel is the object's or not). Stored as an 8-bit
    greyscale PNG (0 or 255). The ground-truth columns (box, visible pixels, visible fraction)
    come from it, so any truth pass renders it.
``depth``
    Distance along the camera axis (Cycles' Z pass) per pixel of the stored image, float32, with
    ``inf`` where no surface is hit. Stored as a compressed ``.npz`` (numpy's own zip of a
    ``.npy``; lossless, read with :func:`decode_depth` or ``np.load(path)["depth"]``).

Both are in the stored image's pixel grid, also under ``resolution = "model"`` (the centre crop).
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

#: The passes that make a truth row (``"uv"``, the part-visibility pass, is keyed apart).
TRUTH_PASSES = ("mask", "depth")
#: Every pass a consumer may ask for.
PASSES = ("depth", "mask", "uv")
#: Bumped when the truth passes or their columns change for the same render (not for a column
#: that rows from before may lack and readers take as unknown: ``framed_pixels``).
TRUTH_VERSION = 1
#: Bumped when the truth rows change for a render that a control's ``edit`` touched (keyed only
#: there, so other renders keep their rows): 2, what an edit adds is an occluder of the silhouette
#: unless it is ``part_of_object`` (it was left in the silhouette render, or ignored).
EDITED_TRUTH_VERSION = 2
#: Blob suffixes under the truth key (``blobs/ab/<truth_key>.<suffix>``).
BLOB_SUFFIX = {"mask": "mask.png", "depth": "depth.npz"}
#: Columns a truth row adds to ``results`` (besides its key).
TRUTH_COLUMNS = ("gt_x0", "gt_y0", "gt_x1", "gt_y1", "visible_pixels", "silhouette_pixels", "visible_fraction",
                 "evaluable")
#: Default of ``[evaluator] min_visible``.
MIN_VISIBLE = 0.1


def box(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """The mask's bounding box ``(x0, y0, x1, y1)`` in pixels, x1 and y1 exclusive; None when empty."""
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return None
    return int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1


def ground_truth(mask: np.ndarray, silhouette: float | None, framed: float | None = None) -> dict[str, Any]:
    """The truth row's numbers from the visible ``mask``, the unoccluded, unclipped silhouette's
    pixel count (None: unknown, e.g. the object reaches behind the camera) and how many of those
    pixels lie in the image (``framed``: with no visible pixel, 0 is out of frame, more is occluded)."""
    visible = int(np.count_nonzero(mask))
    found = box(mask)
    x0, y0, x1, y1 = found if found is not None else (None,) * 4
    fraction = None
    if silhouette is not None:
        fraction = 0.0 if visible == 0 else min(1.0, visible / silhouette) if silhouette > 0 else None
    return {"gt_x0": x0, "gt_y0": y0, "gt_x1": x1, "gt_y1": y1, "visible_pixels": visible,
            "silhouette_pixels": None if silhouette is None else int(round(silhouette)),
            "framed_pixels": None if framed is None else int(round(framed)), "visible_fraction": fraction}


def encode_mask(mask: np.ndarray) -> bytes:
    """A boolean mask as greyscale PNG bytes (255 = the object)."""
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(np.where(mask, 255, 0).astype(np.uint8), mode="L").save(buffer, format="PNG", optimize=True)
    return buffer.getvalue()


def decode_mask(data: bytes) -> np.ndarray:
    """:func:`encode_mask`'s bytes as a boolean (H, W) array."""
    from PIL import Image

    with Image.open(io.BytesIO(data)) as img:
        return np.asarray(img.convert("L")) > 127


def encode_depth(depth: np.ndarray) -> bytes:
    """A float depth map as compressed ``.npz`` bytes (one float32 array named ``depth``)."""
    buffer = io.BytesIO()
    np.savez_compressed(buffer, depth=np.asarray(depth, dtype=np.float32))
    return buffer.getvalue()


def decode_depth(data: bytes) -> np.ndarray:
    """:func:`encode_depth`'s bytes as a float32 (H, W) array."""
    with np.load(io.BytesIO(data), allow_pickle=False) as archive:
        return archive["depth"]
