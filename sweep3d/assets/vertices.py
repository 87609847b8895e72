"""Vertex coordinates that are not finite numbers, found without building geometry.

Blender's importers take a NaN or infinite coordinate without a word (the OBJ importer replaces
it), so the object renders misshapen and its results look valid. These checks read the coordinates
straight from the file with numpy: text OBJ, ASCII and binary PLY and STL, and GLB position
accessors. A layout they do not understand (a PLY whose vertices are not its first element, a
sparse or non-float glTF accessor, a .gltf with separate buffers) is left to Blender.
Coordinates are judged as Blender stores them, in 32 bits: 1e39 is infinite there.
"""

from __future__ import annotations

import json
import re
import struct

import numpy as np

from sweep3d.core import UserError

OBJ_VERTEX = re.compile(rb"(?m)^[ \t]*v[ \t]+([^\n#]*)")
PLAIN = b"0123456789.-+ \t\r"  # what plain decimal numbers are written with
DIGITS = bytes.maketrans(b"123456789", b"000000000")
STL_VERTEX = re.compile(rb"vertex[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)")
PLY_TYPES = {"char": "i1", "uchar": "u1", "int8": "i1", "uint8": "u1", "short": "i2", "ushort": "u2",
             "int16": "i2", "uint16": "u2", "int": "i4", "uint": "u4", "int32": "i4", "uint32": "u4",
             "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
STL_RECORD = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attributes", "<u2")])
GLB_FLOAT = 5126  # glTF componentType of 32-bit floats


def check_obj(data: bytes) -> None:
    """Every number on an OBJ's ``v`` lines (positions, and colours where given) is finite."""
    text = b" ".join(OBJ_VERTEX.findall(data))
    bad = _first_bad(text.split()) if _maybe_not_finite(text) else None
    if bad is None:
        return
    for number, match in enumerate(OBJ_VERTEX.finditer(data), 1):
        words = match.group(1).split()
        if bad < len(words):
            line = data.count(b"\n", 0, match.start()) + 1
            raise _bad_vertex(f"vertex {number} of the OBJ file (line {line})", words[bad])
        bad -= len(words)


def check_ply(data: bytes, body: int, fmt: str, elements: list[tuple[str, int, list[tuple[str, str]]]]) -> None:
    """The x, y, z of a PLY's vertices are finite, when the vertices are its first element and
    have no list properties.

    Args:
        body: where the data after ``end_header`` starts.
        fmt: the header's format (ascii, binary_little_endian, binary_big_endian).
        elements: (name, count, [(type, name), ...]) in header order.
    """
    if not elements or elements[0][0] != "vertex":
        return
    _, count, props = elements[0]
    if not all(kind in PLY_TYPES for kind, _ in props):
        return  # a list property: rows of varying size
    names = [name for _, name in props]
    columns = [names.index(c) for c in ("x", "y", "z") if c in names]
    if not columns or fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        return
    if fmt == "ascii":
        rows = [row.split() for row in data[body:].split(b"\n", count)[:count]]
        if any(len(row) != len(props) for row in rows):
            return  # not one vertex per line: Blender decides
        words = [row[i] for row in rows for i in columns]
        bad = _first_bad(words)
        if bad is not None:
            raise _bad_vertex(f"vertex {bad // len(columns) + 1} of the PLY file", words[bad])
        return
    order = "<" if fmt == "binary_little_endian" else ">"
    dtype = np.dtype([(f"p{i}", order + PLY_TYPES[kind]) for i, (kind, _) in enumerate(props)])
    if len(data) - body < count * dtype.itemsize:
        return  # truncated: the header check says so
    table = np.frombuffer(data, dtype, count=count, offset=body)
    for i in columns:
        bad = _first_bad_value(table[f"p{i}"])
        if bad is not None:
            raise _bad_vertex(f"vertex {bad + 1} of the PLY file", table[f"p{i}"][bad])


def check_stl(data: bytes, binary: bool) -> None:
    """The triangle corners of a binary or ASCII STL are finite (normals are recomputed by Blender)."""
    if binary:
        corners = np.frombuffer(data, STL_RECORD, offset=84)["corners"].reshape(-1)
        bad = _first_bad_value(corners)
        if bad is not None:
            raise _bad_vertex(f"triangle {bad // 9 + 1} of the STL file", corners[bad])
        return
    words = [word for corner in STL_VERTEX.findall(data) for word in corner]
    bad = _first_bad(words)
    if bad is not None:
        raise _bad_vertex(f"vertex {bad // 3 + 1} of the STL file", words[bad])


def check_glb(data: bytes) -> None:
    """The POSITION accessors of a GLB's meshes (float, not sparse, in its binary chunk) are finite."""
    try:
        length, kind = struct.unpack_from("<II", data, 12)
        doc = json.loads(data[20:20 + length]) if kind == 0x4E4F534A else {}
        bin_at = 20 + length
        bin_length = struct.unpack_from("<I", data, bin_at)[0] if len(data) >= bin_at + 8 else 0
    except (struct.error, ValueError, UnicodeDecodeError):
        return  # the structure check reports what is wrong
    chunk = memoryview(data)[bin_at + 8: bin_at + 8 + bin_length]
    for mesh_index, mesh in enumerate(_list(doc, "meshes")):
        for primitive in _list(mesh, "primitives"):
            attributes = primitive.get("attributes")
            positions = _accessor(doc, chunk, attributes.get("POSITION") if isinstance(attributes, dict) else None)
            bad = None if positions is None else _first_bad_value(positions.reshape(-1))
            if bad is not None:
                raise _bad_vertex(f"vertex {bad // 3 + 1} of mesh {mesh_index} of the .glb file",
                                  positions.reshape(-1)[bad])


def _accessor(doc: dict, chunk: memoryview, index: object) -> np.ndarray | None:
    """A VEC3 float accessor's values as a (count, 3) view of the binary chunk, or None."""
    try:
        acc = doc["accessors"][index]
        view = doc["bufferViews"][acc["bufferView"]]
        if acc.get("componentType") != GLB_FLOAT or acc.get("type") != "VEC3" or "sparse" in acc \
                or view.get("buffer", 0) != 0:
            return None
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        stride, count = view.get("byteStride") or 12, int(acc["count"])
        if count <= 0 or start + stride * (count - 1) + 12 > len(chunk):
            return None
        return np.ndarray((count, 3), "<f4", buffer=chunk, offset=start, strides=(stride, 4))
    except (KeyError, IndexError, TypeError, ValueError):
        return None


def _list(doc: object, key: str) -> list:
    value = doc.get(key, []) if isinstance(doc, dict) else []
    return [v for v in value if isinstance(v, dict)] if isinstance(value, list) else []


def _maybe_not_finite(text: bytes) -> bool:
    """Whether numbers written as ``text`` might not be finite in 32 bits: it holds a letter (nan,
    inf, an exponent) or 39 digits in a row. Most meshes hold neither and are not parsed at all."""
    return bool(text.translate(None, PLAIN)) or b"0" * 39 in text.translate(DIGITS)


def _first_bad(words: list[bytes]) -> int | None:
    """The index of the first word that is not a finite 32-bit number (None when all are, or when
    some word is not a number at all: then Blender decides how to read it)."""
    if not words:
        return None
    try:
        values = np.array(words).astype(np.float64)
    except ValueError:
        return None
    return _first_bad_value(values)


def _first_bad_value(values: np.ndarray) -> int | None:
    """The index of the first value that is not finite in 32 bits, or None."""
    with np.errstate(over="ignore", invalid="ignore"):
        finite = np.isfinite(values.astype(np.float32))
    return None if finite.all() else int(np.argmin(finite))


def _bad_vertex(where: str, value: object) -> UserError:
    shown = value.decode("ascii", "replace") if isinstance(value, bytes) else str(value)
    return UserError(f"{where} has the coordinate {shown}, not a finite number: Blender would import it "
                     "without a word and render a misshapen object; fix the mesh or export it again")
