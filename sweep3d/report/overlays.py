"""Ground truth and predictions drawn onto the report's thumbnails, so a failure shows *where* it failed.

Where ``results`` has them (per image key, the shown model's row): the true box (``gt_*``) in
green and the predicted box (``pred_*``, box tasks) in red, as outlines; for segmentation
(``pred_mask``) the true mask (the mask pass's blob) tinted green and the predicted mask red.
Boxes and masks are in the stored image's pixels, so they are scaled with the thumbnail.
A thumbnail with nothing to draw is the plain image, as before.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import duckdb
import numpy as np
from PIL import Image, ImageDraw

from sweep3d.cache import Store
from sweep3d.core import BLOB_SUFFIX, decode_mask

TRUE_COLOR = (0, 230, 0)
PRED_COLOR = (255, 0, 0)
TINT = 0.45  # opacity of a mask's tint
LINE = 2  # box outline width in thumbnail pixels (survives JPEG)
BOX = ("x0", "y0", "x1", "y1")

Box = tuple[float, float, float, float]


@dataclass(frozen=True)
class Overlay:
    """What to draw on one image's thumbnail (None: nothing of that kind)."""

    true_box: Box | None = None
    pred_box: Box | None = None
    true_mask: Path | None = None  # the mask pass's PNG blob
    pred_mask: bytes | None = None  # PNG bytes of the predicted mask

    @property
    def empty(self) -> bool:
        return self.true_box is None and self.pred_box is None and self.true_mask is None and self.pred_mask is None


def read_overlays(con: duckdb.DuckDBPyConnection, store: Store, keys: list[str]) -> dict[str, Overlay]:
    """Image key → its :class:`Overlay`, for ``keys`` with something to draw ({} when ``results``
    has no truth or predicted geometry at all: a classification store without truth passes)."""
    columns = {row[0] for row in con.execute("DESCRIBE results").fetchall()}
    true_box = all(f"gt_{c}" in columns for c in BOX)
    pred_box = all(f"pred_{c}" in columns for c in BOX)
    masks = "pred_mask" in columns
    if not keys or not (true_box or pred_box or masks):
        return {}
    select = ["image_key"]
    select += [f"gt_{c}" if true_box else "NULL" for c in BOX] + [f"pred_{c}" if pred_box else "NULL" for c in BOX]
    select += ["truth_key" if masks and "truth_key" in columns else "NULL", "pred_mask" if masks else "NULL"]
    found = con.execute(
        f"SELECT {', '.join(select)} FROM results WHERE list_contains(?, image_key) "
        "QUALIFY row_number() OVER (PARTITION BY image_key ORDER BY job) = 1", [keys]).fetchall()
    out = {}
    for key, *values in found:
        truth_key, pred_mask = values[8:]
        overlay = Overlay(
            true_box=_box(values[0:4]), pred_box=_box(values[4:8]),
            true_mask=store.blob_path(truth_key, BLOB_SUFFIX["mask"]) if truth_key else None,
            pred_mask=bytes(pred_mask) if pred_mask is not None else None)
        if not overlay.empty:
            out[key] = overlay
    return out


def draw_overlay(thumb: Image.Image, overlay: Overlay, scale: tuple[float, float]) -> Image.Image:
    """``thumb`` (RGB) with ``overlay`` drawn on it; ``scale`` maps stored-image pixels to the
    thumbnail's (x, y). A mask that cannot be read is left out; the boxes are still drawn."""
    out = thumb.copy()
    for mask, color in ((_read_mask(overlay.true_mask), TRUE_COLOR), (_decode(overlay.pred_mask), PRED_COLOR)):
        if mask is not None:
            out = _tint(out, mask, color)
    pen = ImageDraw.Draw(out)
    for box, color in ((overlay.true_box, TRUE_COLOR), (overlay.pred_box, PRED_COLOR)):
        if box is not None:
            _outline(pen, box, scale, out.size, color)
    return out


def _outline(pen: ImageDraw.ImageDraw, box: Box, scale: tuple[float, float], size: tuple[int, int],
             color: tuple[int, int, int]) -> None:
    """The box's outline, inside its scaled extent (x1, y1 exclusive), clipped to the thumbnail."""
    sx, sy = scale
    x0, x1 = sorted((box[0] * sx, box[2] * sx))
    y0, y1 = sorted((box[1] * sy, box[3] * sy))
    left, top = max(0, round(x0)), max(0, round(y0))
    right, bottom = min(size[0], round(x1)) - 1, min(size[1], round(y1)) - 1
    if right < left or bottom < top:
        return
    pen.rectangle([left, top, right, bottom], outline=color, width=LINE)


def _tint(img: Image.Image, mask: np.ndarray, color: tuple[int, int, int]) -> Image.Image:
    """``img`` with ``color`` blended in over ``mask`` (any size: resized to the image's, as coverage)."""
    cover = Image.fromarray(mask.astype(np.uint8) * 255, mode="L").resize(img.size, Image.Resampling.BILINEAR)
    alpha = np.asarray(cover, dtype=np.float32)[..., None] / 255.0 * TINT
    pixels = np.asarray(img, dtype=np.float32)
    blended = pixels * (1 - alpha) + np.array(color, dtype=np.float32) * alpha
    return Image.fromarray(np.round(blended).astype(np.uint8), mode="RGB")


def _read_mask(path: Path | None) -> np.ndarray | None:
    if path is None:
        return None
    try:
        return _decode(path.read_bytes())
    except OSError:
        return None


def _decode(data: bytes | None) -> np.ndarray | None:
    if not data:
        return None
    try:
        return decode_mask(data)
    except (OSError, ValueError):
        return None


def _box(values: list) -> Box | None:
    if any(v is None for v in values):
        return None
    box = tuple(float(v) for v in values)
    return box if all(np.isfinite(box)) else None
