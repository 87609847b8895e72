"""An OBJ file and its MTL materials as Blender's importer makes them, without Blender.

The Mitsuba engine must show the object Cycles shows, so this reader follows Blender 4's OBJ
importer (defaults: forward -Z, up Y; one object per ``o``): Blender's (x, y, z) is the file's
(x, -z, y); a face is smooth where ``s`` is on, with the file's ``vn`` when it has them, else with
vertex normals averaged over the object's smooth faces (weighted by each corner's angle, as
Blender does); an MTL becomes the Principled BSDF values the importer sets (``base_color`` from
``Kd`` or ``map_Kd``, ``roughness`` = 1 − √(Ns / 1000), ``specular`` = the mean of ``Ks``, ``ior``
= ``Ni``, ``opacity`` = ``d``, ``metallic`` = ``Pm`` (else 1 for illum 3–7), ``transmission`` =
the mean of ``Tf``, ``coat`` = ``Pc`` / 4; ``sweep3d plan --materials`` shows Blender's own). Faces are triangulated as fans and every
corner gets its own vertex, so the arrays are ready for a triangle mesh.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sweep3d.core import UserError

DEFAULT_MATERIAL = ""  # faces before any usemtl, or naming a material the MTL lacks


@dataclass(frozen=True)
class MtlMaterial:
    """One ``newmtl`` as the Principled BSDF inputs Blender's importer gives it (linear colours)."""

    name: str
    base_color: tuple[float, float, float] = (0.8, 0.8, 0.8)
    texture: str | None = None  # map_Kd, an absolute path
    roughness: float = 0.5
    metallic: float = 0.0
    specular: float = 0.5  # Blender's Specular IOR Level
    ior: float = 1.5
    opacity: float = 1.0
    transmission: float = 0.0  # the mean of Tf
    coat: float = 0.0  # a quarter of Pc


@dataclass
class Piece:
    """Triangles of one object of the file with one material: three vertices per triangle."""

    object_name: str
    material: str
    positions: np.ndarray  # (3n, 3) float64, Blender's axes
    normals: np.ndarray  # (3n, 3) float32, unit
    uvs: np.ndarray | None  # (3n, 2) float32, OBJ's (v up); None without vt


@dataclass
class ObjMesh:
    """A file's pieces and materials."""

    pieces: list[Piece] = field(default_factory=list)
    materials: dict[str, MtlMaterial] = field(default_factory=dict)

    def objects(self) -> list[str]:
        """The file's object names, in file order."""
        return list(dict.fromkeys(p.object_name for p in self.pieces))


def read_obj(path: Path) -> ObjMesh:
    """Read ``path`` (and the MTL files it names) into pieces ready to render.

    Raises:
        UserError: the file cannot be read or has an index out of range.
    """
    try:
        text = path.read_text(errors="replace")
    except OSError as exc:
        raise UserError(f"cannot read the mesh {str(path)!r}: {exc.strerror}") from None
    positions: list[tuple[float, float, float]] = []
    texcoords: list[tuple[float, float]] = []
    normals: list[tuple[float, float, float]] = []
    # per object, per (material, smooth): lists of corner triples (v, vt, vn), 0-based, -1 = none
    faces: dict[str, dict[tuple[str, bool], list[tuple[int, int, int]]]] = {}
    libraries: list[str] = []
    obj = path.stem
    material, smooth = DEFAULT_MATERIAL, False
    for number, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        tag = parts[0]
        try:
            if tag == "v":
                positions.append((float(parts[1]), float(parts[2]), float(parts[3])))
            elif tag == "vt":
                texcoords.append((float(parts[1]), float(parts[2]) if len(parts) > 2 else 0.0))
            elif tag == "vn":
                normals.append((float(parts[1]), float(parts[2]), float(parts[3])))
            elif tag == "f":
                corners = [_corner(c, len(positions), len(texcoords), len(normals)) for c in parts[1:]]
        except (IndexError, ValueError):
            raise UserError(f"{path}:{number}: cannot read {line.strip()[:60]!r} (a '{tag}' line needs numbers: "
                            "fix or re-export the mesh)") from None
        if tag == "f":
            bucket = faces.setdefault(obj, {}).setdefault((material, smooth), [])
            for tri in triangulate([positions[c[0]] for c in corners]):
                bucket += (corners[tri[0]], corners[tri[1]], corners[tri[2]])
        elif tag == "o" and len(parts) > 1:
            obj = " ".join(parts[1:])
        elif tag == "usemtl":
            material = " ".join(parts[1:])
        elif tag == "s":
            smooth = len(parts) > 1 and parts[1] not in ("off", "0")
        elif tag == "mtllib":
            libraries.append(" ".join(parts[1:]))
    mesh = ObjMesh(materials=_materials(path.parent, libraries))
    points = _blender_axes(np.asarray(positions, dtype=np.float64).reshape(-1, 3))
    vt = np.asarray(texcoords, dtype=np.float32).reshape(-1, 2)
    vn = _blender_axes(np.asarray(normals, dtype=np.float64).reshape(-1, 3))
    for name, buckets in faces.items():
        smooth_normals = _smooth_normals(points, [c for (_, s), cs in buckets.items() if s for c in cs])
        for (mat, is_smooth), corners in buckets.items():
            if not corners:
                continue
            index = np.asarray(corners, dtype=np.int64)
            p = points[index[:, 0]]
            face_n = _face_normals(p)
            if not is_smooth:
                n = np.repeat(face_n, 3, axis=0)
            elif (index[:, 2] >= 0).all():
                n = vn[index[:, 2]]
            else:
                n = smooth_normals[index[:, 0]]
            flat = np.repeat(face_n, 3, axis=0)
            n = _unit(n, flat)
            n = np.where(((n * flat).sum(axis=1) < 0.0)[:, None], flat, n)  # a smooth normal facing away
            uvs = vt[np.maximum(index[:, 1], 0)] if len(vt) and (index[:, 1] >= 0).all() else None
            known = mat if mat in mesh.materials else DEFAULT_MATERIAL
            mesh.pieces.append(Piece(name, known, p, n.astype(np.float32), uvs))
    return mesh


def triangulate(polygon: list[tuple[float, float, float]]) -> list[tuple[int, int, int]]:
    """A face's triangles as corner indices: a fan for a convex face (as Blender splits a quad),
    ear clipping in the face's plane for a concave one (an n-gon around a hole's bridge, which a
    fan would cover), so no triangle lies outside the face."""
    n = len(polygon)
    fan = [(0, i, i + 1) for i in range(1, n - 1)]
    if n <= 3:
        return fan
    p = np.asarray(polygon, dtype=np.float64)
    normal = np.cross(p - p.mean(axis=0), np.roll(p, -1, axis=0) - p.mean(axis=0)).sum(axis=0)  # Newell
    if not np.linalg.norm(normal) > 0:
        return fan
    axis = int(np.argmax(np.abs(normal)))
    xy = np.delete(p, axis, axis=1)  # seen from +axis; (x, z) is seen from -y
    if (normal[axis] > 0) == (axis == 1):
        xy[:, 0] = -xy[:, 0]  # mirrored, so the face turns counter-clockwise
    turn = [_cross2(xy[i - 1], xy[i], xy[(i + 1) % n]) for i in range(n)]
    if min(turn) >= 0:  # convex (counter-clockwise in the plane)
        return fan
    return _ear_clip(xy) or fan


def _cross2(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    return float((b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0]))


def _ear_clip(xy: np.ndarray) -> list[tuple[int, int, int]]:
    """Ear clipping of a counter-clockwise simple polygon (empty when it finds no ear: not simple)."""
    left = list(range(len(xy)))
    out: list[tuple[int, int, int]] = []
    while len(left) > 3:
        for k in range(len(left)):
            a, b, c = left[k - 1], left[k], left[(k + 1) % len(left)]
            if _cross2(xy[a], xy[b], xy[c]) <= 0:
                continue  # reflex
            inside = any(_in_triangle(xy[q], xy[a], xy[b], xy[c]) for q in left if q not in (a, b, c))
            if not inside:
                out.append((a, b, c))
                left.pop(k)
                break
        else:
            return []
    out.append((left[0], left[1], left[2]))
    return out


def _in_triangle(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> bool:
    return _cross2(a, b, p) >= 0 and _cross2(b, c, p) >= 0 and _cross2(c, a, p) >= 0


def _corner(token: str, nv: int, nt: int, nn: int) -> tuple[int, int, int]:
    """``v[/vt][/vn]`` as 0-based indices (negative ones count back from the end), -1 when absent."""
    fields = token.split("/")
    out = []
    for i, count in enumerate((nv, nt, nn)):
        raw = fields[i] if i < len(fields) else ""
        if not raw:
            out.append(-1)
            continue
        k = int(raw)
        k = k - 1 if k > 0 else count + k
        if not 0 <= k < count:
            raise UserError(f"the mesh has a face index {raw} out of range (only {count} defined before it)")
        out.append(k)
    if out[0] < 0:
        raise UserError(f"the mesh has a face corner without a vertex: {token!r}")
    return out[0], out[1], out[2]


def _blender_axes(a: np.ndarray) -> np.ndarray:
    """OBJ's Y-up axes as Blender's importer turns them: (x, y, z) → (x, -z, y)."""
    return np.stack([a[:, 0], -a[:, 2], a[:, 1]], axis=1) if len(a) else a.reshape(-1, 3)


def _face_normals(p: np.ndarray) -> np.ndarray:
    """Each triangle's unit normal ((n, 3) from (3n, 3) corners; zero for a degenerate one)."""
    tri = p.reshape(-1, 3, 3)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 0, n / np.where(length > 0, length, 1.0), 0.0)


def _smooth_normals(points: np.ndarray, corners: list[tuple[int, int, int]]) -> np.ndarray:
    """Vertex normals over the smooth faces: face normals weighted by each corner's angle."""
    out = np.zeros_like(points)
    if not corners:
        return out
    v = np.asarray(corners, dtype=np.int64)[:, 0].reshape(-1, 3)
    tri = points[v]
    face_n = _face_normals(tri.reshape(-1, 3))
    for k in range(3):
        a = tri[:, (k + 1) % 3] - tri[:, k]
        b = tri[:, (k + 2) % 3] - tri[:, k]
        cos = (a * b).sum(1) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-30)
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        np.add.at(out, v[:, k], face_n * angle[:, None])
    return out


def _unit(n: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 1e-12, n / np.where(length > 1e-12, length, 1.0), fallback)


def _materials(folder: Path, libraries: list[str]) -> dict[str, MtlMaterial]:
    """Every material of the MTL files named (a missing file gives none, as in Blender)."""
    out: dict[str, MtlMaterial] = {}
    for library in libraries:
        file = folder / library
        if not file.is_file():
            continue
        current: dict[str, str] = {}
        name = None
        for line in file.read_text(errors="replace").splitlines():
            parts = line.split(maxsplit=1)
            if not parts:
                continue
            if parts[0] == "newmtl":
                if name is not None:
                    out[name] = _material(name, current, file.parent)
                name, current = (parts[1].strip() if len(parts) > 1 else ""), {}
            elif len(parts) > 1:
                current[parts[0]] = parts[1].strip()
        if name is not None:
            out[name] = _material(name, current, file.parent)
    return out


def _material(name: str, values: dict[str, str], folder: Path) -> MtlMaterial:
    """One ``newmtl`` block as Blender's importer's Principled BSDF values."""

    def number(key: str, default: float) -> float:
        try:
            return float(values[key].split()[0])
        except (KeyError, ValueError, IndexError):
            return default

    def colour(key: str) -> tuple[float, float, float] | None:
        try:
            rgb = [float(x) for x in values[key].split()[:3]]
        except (KeyError, ValueError):
            return None
        return (rgb[0], rgb[0], rgb[0]) if len(rgb) == 1 else tuple(rgb) if len(rgb) == 3 else None  # type: ignore[return-value]

    kd = colour("Kd") or (0.8, 0.8, 0.8)
    ks = colour("Ks")
    texture = None
    if "map_Kd" in values:
        file = folder / values["map_Kd"].split()[-1]
        texture = str(file) if file.is_file() else None
    ns = number("Ns", -1.0)
    roughness = number("Pr", -1.0)
    if roughness < 0:
        roughness = 1.0 - math.sqrt(min(max(ns, 0.0), 1000.0) / 1000.0) if ns >= 0 else 0.5
    metallic = number("Pm", -1.0)
    if metallic < 0:  # Blender: reflection on (illum 3-7) is a metal
        metallic = 1.0 if 3 <= number("illum", -1.0) <= 7 else 0.0
    tf = colour("Tf")
    return MtlMaterial(name=name, base_color=kd, texture=texture, roughness=roughness, metallic=metallic,
                       specular=sum(ks) / 3.0 if ks is not None else 0.5, ior=number("Ni", 1.5),
                       opacity=min(max(number("d", 1.0), 0.0), 1.0),
                       transmission=min(max(sum(tf) / 3.0, 0.0), 1.0) if tf is not None else 0.0,
                       coat=max(number("Pc", 0.0), 0.0) / 4.0)
