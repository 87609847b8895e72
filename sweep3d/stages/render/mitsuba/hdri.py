"""World maps for Mitsuba with the values Blender renders: read once per worker, as Blender reads them.

Blender reads an EXR's pixels as they are (its colour space "Linear Rec.709") and ignores the
file's ``chromaticities`` attribute; Mitsuba's reader converts pixels from those primaries to
Rec.709. For a file that carries them (the bpy wheel's ``city.exr`` does), the conversion is
undone here with the same matrices (OpenEXR's RGB→XYZ of the file's primaries, then XYZ→RGB of
Rec.709, D65), so both engines light and show the same numbers.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import numpy as np

#: OpenEXR's default chromaticities (Rec.709 primaries, D65 white): red, green, blue, white (x, y).
REC709 = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
HEADER_BYTES = 1 << 16


def exr_chromaticities(path: Path) -> tuple[float, ...] | None:
    """The ``chromaticities`` attribute of an OpenEXR file's header (8 floats), None when absent
    or when the file is not an EXR."""
    try:
        with open(path, "rb") as f:
            data = f.read(HEADER_BYTES)
    except OSError:
        return None
    if data[:4] != b"\x76\x2f\x31\x01":
        return None
    pos = 8
    try:
        while data[pos] != 0:
            end = data.index(b"\0", pos)
            pos = end + 1
            end = data.index(b"\0", pos)
            kind = data[pos:end]
            pos = end + 1
            size = struct.unpack_from("<i", data, pos)[0]
            pos += 4
            if kind == b"chromaticities" and size == 32:
                return struct.unpack_from("<8f", data, pos)
            pos += size
    except (ValueError, IndexError, struct.error):
        return None
    return None


def rgb_to_xyz(chroma: tuple[float, ...]) -> np.ndarray:
    """3×3 matrix from RGB with these primaries and white (x, y pairs) to XYZ, white at Y = 1."""
    xy = np.asarray(chroma, dtype=np.float64).reshape(4, 2)
    xyz = np.stack([xy[:, 0] / xy[:, 1], np.ones(4), (1.0 - xy[:, 0] - xy[:, 1]) / xy[:, 1]], axis=1)
    primaries, white = xyz[:3].T, xyz[3]
    return primaries * np.linalg.solve(primaries, white)


def undo_conversion(chroma: tuple[float, ...]) -> np.ndarray | None:
    """The matrix taking Mitsuba's converted pixels back to the file's own values (None: Mitsuba
    converted nothing, the primaries being Rec.709's)."""
    if np.allclose(chroma, REC709, atol=1e-4):
        return None
    converted = np.linalg.solve(rgb_to_xyz(REC709), rgb_to_xyz(chroma))  # file RGB → Rec.709
    return np.linalg.inv(converted)


def load_bitmap(mi: Any, path: str) -> Any:
    """The map as a Mitsuba ``Bitmap`` holding the values Blender renders (module docstring)."""
    bitmap = mi.Bitmap(path)
    chroma = exr_chromaticities(Path(path))
    matrix = undo_conversion(chroma) if chroma is not None else None
    if matrix is None:
        return bitmap
    pixels = np.array(bitmap, dtype=np.float32)
    rgb = np.maximum(pixels[..., :3] @ matrix.T.astype(np.float32), 0.0)
    return mi.Bitmap(np.ascontiguousarray(rgb, dtype=np.float32))
