"""An OBJ's vertex lines and faces, checked when the spec loads rather than when Blender renders.

Blender's OBJ importer takes ``v 0 0`` as a vertex at z = 0, drops a face that names a vertex the
file does not have, and imports faces whose corners coincide or lie on a line; the first two
render a different object than the file says, the last two leave nothing to render, found only
by the render worker after the plan was made. These checks read the numbers with numpy (no
geometry is built) and say the line to fix. Faces with relative (negative) indices are judged
for their range only; their area is left to Blender, as it depends on where they are in the file.
"""

from __future__ import annotations

import re

import numpy as np

from sweep3d.core import UserError

#: A ``v`` line with fewer than three numbers (a comment may follow).
SHORT_VERTEX = re.compile(rb"(?m)^[ \t]*v(?:[ \t]+[^\s#]+){0,2}[ \t]*(?:#[^\n]*)?\r?$")
VERTEX = re.compile(rb"(?m)^[ \t]*v[ \t]+([^\n#]*)")
FACE = re.compile(rb"(?m)^[ \t]*f[ \t]+([^\n#]*)")
CORNER_TAIL = re.compile(rb"/[^\s]*")  # a corner's texture and normal indices: 3/1/2 -> 3
#: Total face area (relative to the mesh's squared size) below which every face is degenerate.
ZERO_AREA = 1e-12
FIX = "fix the mesh or export it again"


def check_obj_geometry(data: bytes) -> None:
    """Every ``v`` line has x, y and z; every face names vertices the file has; some face has area.

    Raises:
        UserError: naming the line of the OBJ file to fix (or the whole file, for zero area).
    """
    short = SHORT_VERTEX.search(data)
    if short is not None:
        found = short.group().strip().decode("utf-8", "replace")
        raise UserError(f"line {_line(data, short.start())} of the OBJ file, {found!r}, has fewer than three "
                        f"coordinates; a vertex needs x y z: {FIX}")
    vertices = VERTEX.findall(data)
    faces = FACE.findall(data)
    corners = _corners(faces)
    if corners is None:
        return  # a corner that is not a whole number: Blender decides
    indices, counts = corners
    bad = (indices == 0) | (indices > len(vertices)) | (indices < -len(vertices))
    if bad.any():
        face = int(np.searchsorted(np.cumsum(counts), int(np.argmax(bad)), side="right"))
        at = next(m for i, m in enumerate(FACE.finditer(data)) if i == face)
        raise UserError(f"line {_line(data, at.start())} of the OBJ file: face {face + 1} refers to vertex "
                        f"{int(indices[np.argmax(bad)])}, but the file has {len(vertices)} vertices (numbered from "
                        f"1); Blender would drop the face: {FIX}")
    if (indices > 0).all() and _all_degenerate(vertices, indices - 1, counts):
        raise UserError("every face of the OBJ file has zero area (its corners coincide or lie on a line), so "
                        f"nothing would be rendered: {FIX}")


def _line(data: bytes, at: int) -> int:
    return data.count(b"\n", 0, at) + 1


def _corners(faces: list[bytes]) -> tuple[np.ndarray, np.ndarray] | None:
    """Each face's vertex indices, flat (as written: 1-based or negative), and the corners per face."""
    words = [CORNER_TAIL.sub(b"", face).split() for face in faces]
    try:
        indices = np.array([w for face in words for w in face], dtype=np.int64)
    except (ValueError, OverflowError):
        return None
    return indices, np.array([len(face) for face in words], dtype=np.int64)


def _all_degenerate(vertices: list[bytes], indices: np.ndarray, counts: np.ndarray) -> bool:
    """Whether the faces' fan triangles have no area at all (relative to the mesh's size)."""
    try:
        points = np.array([line.split()[:3] for line in vertices], dtype=np.float64)
    except ValueError:
        return False  # a coordinate that is not a number: Blender decides
    keep = counts >= 3
    if not keep.any():
        return True
    starts, fans = (np.cumsum(counts) - counts)[keep], counts[keep] - 2
    first = np.repeat(starts, fans)
    j = np.arange(fans.sum()) - np.repeat(np.cumsum(fans) - fans, fans)
    a, b, c = (points[indices[first + k]] for k in (0, j + 1, j + 2))
    area = np.linalg.norm(np.cross(b - a, c - a), axis=1).sum() / 2
    size = np.ptp(points[indices], axis=0).max()
    return bool(area <= ZERO_AREA * size**2)
