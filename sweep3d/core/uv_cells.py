"""The parts of an object's surface that the part-visibility panel conditions on (no bpy here).

A *part* is a cell of a longitude/latitude grid around the object's centre, in the object's own
normalised frame (front = -Y, up = +Z): 16 slices of azimuth × 8 bands of elevation, 22.5° each.
Every mesh of an object file shares this one parameterisation, which the mesh's own UV atlas
(often absent, often split into islands that mean nothing together) cannot promise. The
renderer writes it as a dedicated UV map, ``sweep3d_parts``, and reads it back through Cycles'
UV pass; :func:`part_counts` turns one pass into pixels per part.

UV layout: ``u = azimuth turn / 2`` and ``v = elevation turn``, so a face that straddles the seam
at the back (azimuth ±180°) can keep a continuous ``u`` past one turn (up to 0.75) instead of
wrapping through the whole map, and a 16-bit image holds it without clipping.
"""

from __future__ import annotations

import numpy as np

AZIMUTH_PARTS = 16
ELEVATION_PARTS = 8
PARTS = AZIMUTH_PARTS * ELEVATION_PARTS
#: Names this layout in cache keys: changing the grid or the encoding must change it.
PARTS_LAYOUT = f"sphere-{AZIMUTH_PARTS}x{ELEVATION_PARTS}-v1"
UV_MAP = "sweep3d_parts"


def sphere_turns(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth and elevation of ``points`` (N, 3) as turns: azimuth in [0, 1) with the front
    (-Y) at 0.5 and the seam at the back; elevation in [0, 1] from below to above.

    The centre itself and non-finite points get the front-equator direction (0.5, 0.5).
    """
    p = np.nan_to_num(np.asarray(points, dtype=np.float64).reshape(-1, 3), nan=0.0, posinf=0.0, neginf=0.0)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    azimuth = np.arctan2(x, -y) / (2 * np.pi) + 0.5  # front (-Y) → 0.5, right (+X) → 0.75
    elevation = np.arctan2(z, np.hypot(x, y)) / np.pi + 0.5
    return np.mod(azimuth, 1.0), np.clip(elevation, 0.0, 1.0)


def loop_uvs(points: np.ndarray, loop_vertices: np.ndarray, loop_starts: np.ndarray) -> np.ndarray:
    """UVs (L, 2) for a mesh's face corners ("loops") in the layout above.

    Args:
        points: vertex positions (V, 3) in the object's normalised frame.
        loop_vertices: the vertex index of each loop (L,).
        loop_starts: the first loop of each face (F,), ascending.
    """
    azimuth, elevation = sphere_turns(points)
    u = azimuth[loop_vertices]
    if len(loop_starts):
        # A face whose corners span more than half a turn crosses the seam at the back: move its
        # corners on the near side of the seam one turn on, so the face interpolates across it.
        spread = np.maximum.reduceat(u, loop_starts) - np.minimum.reduceat(u, loop_starts)
        face_of_loop = np.repeat(np.arange(len(loop_starts)), np.diff(np.append(loop_starts, len(u))))
        u = np.where((spread[face_of_loop] > 0.5) & (u < 0.5), u + 1.0, u)
    return np.stack([u / 2.0, elevation[loop_vertices]], axis=1).astype(np.float32)


def part_of(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The part index (row-major: elevation band × azimuth slice) of stored UVs ``u``, ``v``."""
    azimuth = np.floor(np.nan_to_num(np.asarray(u, dtype=np.float64) * 2.0) * AZIMUTH_PARTS).astype(np.int64)
    band = np.floor(np.nan_to_num(np.asarray(v, dtype=np.float64)) * ELEVATION_PARTS).astype(np.int64)
    return np.clip(band, 0, ELEVATION_PARTS - 1) * AZIMUTH_PARTS + np.mod(azimuth, AZIMUTH_PARTS)


def part_counts(u: np.ndarray, v: np.ndarray, mask: np.ndarray) -> dict[str, object]:
    """Pixels per visible part of one UV pass.

    The object's silhouette is eroded by one pixel first: Cycles averages the UV pass over a
    pixel's samples, so a pixel half on the background holds half a UV, i.e. a wrong part.

    Args:
        u, v: the stored UVs per pixel (H, W); mask: True where the object is (H, W).

    Returns:
        ``parts`` (visible part indices, ascending), ``pixels`` (each one's pixel count) and
        ``object_pixels`` (pixels counted in all).
    """
    inner = np.asarray(mask, dtype=bool).copy()
    inner[0, :] = inner[-1, :] = inner[:, 0] = inner[:, -1] = False
    core = inner[1:-1, 1:-1]
    core &= inner[:-2, 1:-1] & inner[2:, 1:-1] & inner[1:-1, :-2] & inner[1:-1, 2:]
    if not inner.any():
        return {"parts": [], "pixels": [], "object_pixels": 0}
    counts = np.bincount(part_of(u[inner], v[inner]), minlength=PARTS)
    visible = np.flatnonzero(counts)
    return {"parts": visible.tolist(), "pixels": counts[visible].tolist(), "object_pixels": int(counts.sum())}


def part_bounds(part: int) -> tuple[float, float, float, float]:
    """(azimuth from, azimuth to, elevation from, elevation to) of ``part`` in degrees, with the
    front at azimuth 0, the object's right at +90 and the back at ±180."""
    band, slice_ = divmod(part, AZIMUTH_PARTS)
    width, height = 360.0 / AZIMUTH_PARTS, 180.0 / ELEVATION_PARTS
    return (-180.0 + slice_ * width, -180.0 + (slice_ + 1) * width, -90.0 + band * height, -90.0 + (band + 1) * height)
