"""Cheap checks that a mesh or HDRI file is what its name says, before Blender sees it.

Blender imports a random-bytes OBJ as "no mesh", a vertex-only OBJ as an empty picture, and
loads a truncated or non-image HDRI as a magenta "missing texture" world without any error.
These checks read the file's header and structure (never decode pixels or build geometry),
so a broken asset fails at spec load with a one-line error instead of rendering garbage.
They are conservative: a file they cannot judge (a multi-part or tiled EXR) passes, and
Blender's own errors in the render worker still become one-line user errors.
"""

from __future__ import annotations

import json
import math
import os
import re
import struct
import zipfile
from functools import lru_cache
from pathlib import Path

from sweep3d.errors import UserError

EXR_MAGIC = b"\x76\x2f\x31\x01"
#: Scanlines per chunk for each OpenEXR compression (NONE, RLE, ZIPS, ZIP, PIZ, PXR24, B44, B44A, DWAA, DWAB).
EXR_LINES = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32, 5: 16, 6: 32, 7: 32, 8: 32, 9: 256}


def check_mesh(ref: str) -> None:
    """Check a resolved mesh reference (a path, or ``archive.zip#member``).

    Raises:
        UserError: the file is empty, binary where text is expected, has no faces, or its
            header or size contradicts its format.
    """
    archive, sep, member = ref.partition("#")
    stat = os.stat(archive)
    _check_mesh(archive, member if sep else "", stat.st_size, stat.st_mtime_ns)


def check_hdri(path: str) -> None:
    """Check that an HDRI file holds an image of the format its name says, and is complete.

    Raises:
        UserError: the file is empty, not an image of that format, or truncated.
    """
    stat = os.stat(path)
    _check_hdri(path, stat.st_size, stat.st_mtime_ns)


@lru_cache(maxsize=256)
def _check_mesh(archive: str, member: str, size: int, mtime_ns: int) -> None:
    if member:
        with zipfile.ZipFile(archive) as zf:
            data = zf.read(member)
        name = member
    else:
        data = Path(archive).read_bytes()
        name = archive
    suffix = Path(name).suffix.lower()
    if not data.strip():
        raise UserError("the mesh file is empty; export the mesh again")
    {".obj": _obj, ".ply": _ply, ".stl": _stl, ".glb": _glb, ".gltf": _gltf}.get(suffix, lambda d: None)(data)


def _obj(data: bytes) -> None:
    if b"\x00" in data[:1 << 16]:
        raise UserError("not a text OBJ file (it holds binary bytes); export the mesh as Wavefront OBJ again")
    if not re.search(rb"(?m)^[ \t]*v[ \t]", data):
        raise UserError("the OBJ file has no vertices ('v' lines); export the mesh again")
    if not re.search(rb"(?m)^[ \t]*f[ \t]", data):
        raise UserError("the OBJ file has no faces ('f' lines), so nothing would be rendered; export it with faces")


def _ply(data: bytes) -> None:
    end = data.find(b"end_header", 0, 1 << 16)
    if not data.startswith(b"ply") or end < 0:
        raise UserError("not a PLY file (no 'ply' ... 'end_header' header); export the mesh again")
    header = data[:end].decode("ascii", errors="replace").split("\n")
    fmt = next((line.split()[1] for line in header if line.startswith("format ") and len(line.split()) > 1), "")
    counts: dict[str, int] = {}
    props: dict[str, list[str]] = {}
    element = None
    for line in header:
        words = line.split()
        if len(words) >= 3 and words[0] == "element":
            element = words[1]
            counts[element] = int(words[2]) if words[2].isdigit() else -1
            props[element] = []
        elif len(words) >= 3 and words[0] == "property" and element is not None:
            props[element].append(words[1])
    if counts.get("vertex", 0) <= 0:
        raise UserError("the PLY file declares no vertices; export the mesh again")
    if counts.get("face", 0) <= 0:
        raise UserError("the PLY file has no faces (a point cloud), so nothing would be rendered; export it with faces")
    if fmt.startswith("binary"):
        sizes = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
                 "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}
        vertex = props.get("vertex", [])
        if vertex and all(p in sizes for p in vertex):
            body = len(data) - data.find(b"\n", end) - 1
            needed = counts["vertex"] * sum(sizes[p] for p in vertex)
            if body < needed:
                raise UserError(f"the PLY file is truncated ({body} bytes of data, its {counts['vertex']} vertices "
                                f"need {needed}); copy or export it again")


def _stl(data: bytes) -> None:
    if len(data) >= 84:
        (triangles,) = struct.unpack_from("<I", data, 80)
        if triangles > 0 and len(data) == 84 + 50 * triangles:
            return
    head = data[:1 << 16].lstrip().lower()
    if head.startswith(b"solid") and b"facet" in head and b"vertex" in head:
        return
    raise UserError("not an STL file (neither a binary STL whose size matches its triangle count, nor an ASCII "
                    "'solid ... facet ... vertex' file); export the mesh again")


def _glb(data: bytes) -> None:
    if len(data) < 12 or data[:4] != b"glTF":
        raise UserError("not a binary glTF file (no 'glTF' magic); export the mesh as .glb again")
    _, length = struct.unpack_from("<II", data, 4)
    if length != len(data):
        raise UserError(f"the .glb file is {len(data)} bytes but its header says {length} (truncated or padded); "
                        "copy or export it again")


def _gltf(data: bytes) -> None:
    try:
        doc = json.loads(data)
    except (ValueError, UnicodeDecodeError) as exc:
        raise UserError(f"not glTF JSON ({str(exc).splitlines()[0]}); export the mesh as .gltf or .glb again") from None
    if not isinstance(doc, dict) or "asset" not in doc:
        raise UserError("not a glTF document (no 'asset' entry); export the mesh as .gltf or .glb again")


@lru_cache(maxsize=64)
def _check_hdri(path: str, size: int, mtime_ns: int) -> None:
    suffix = Path(path).suffix.lower()
    with open(path, "rb") as fh:
        data = fh.read()
    if not data:
        raise UserError("the HDRI file is empty; give an .exr or .hdr image")
    if suffix == ".exr":
        _exr(data)
    elif suffix == ".hdr":
        if not (data.startswith(b"#?RADIANCE") or data.startswith(b"#?RGBE")):
            raise UserError("not a Radiance .hdr image (no '#?RADIANCE' header); give an .exr or .hdr image")
        if not re.search(rb"\n\n[-+][YX] \d+ [-+][XY] \d+\n.", data[:1 << 16], re.S):
            raise UserError("the .hdr image has no resolution line or no pixels (truncated?); save it again")
    elif suffix in (".png", ".jpg", ".jpeg", ".tif", ".tiff"):
        _pil_image(path)


def _pil_image(path: str) -> None:
    from PIL import Image

    try:
        with Image.open(path) as img:
            img.verify()
    except Exception as exc:  # noqa: BLE001  (any decoder complaint means a broken image)
        raise UserError(f"not a readable image ({exc}); save it again as .exr or .hdr") from None


def _exr(data: bytes) -> None:
    """OpenEXR: magic, then for single-part scanline files, a complete chunk offset table."""
    if data[:4] != EXR_MAGIC:
        raise UserError("not an OpenEXR image (no EXR magic number); give an .exr or .hdr image")
    flags = struct.unpack_from("<I", data, 4)[0] >> 8
    if flags & (0x2 | 0x8 | 0x10):  # tiled, deep or multi-part: leave those to Blender
        return
    truncated = UserError("the EXR image is truncated (its header or pixel chunks end early); save it again")
    attrs: dict[str, bytes] = {}
    pos = 8
    try:
        while data[pos] != 0:
            name_end = data.index(b"\0", pos)
            type_end = data.index(b"\0", name_end + 1)
            (length,) = struct.unpack_from("<i", data, type_end + 1)
            start = type_end + 5
            if length < 0 or start + length > len(data):
                raise truncated
            attrs[data[pos:name_end].decode("latin-1")] = data[start : start + length]
            pos = start + length
        pos += 1
        if "dataWindow" not in attrs or "compression" not in attrs:
            raise UserError("the EXR header lacks dataWindow or compression; save the image again")
        _, ymin, _, ymax = struct.unpack("<iiii", attrs["dataWindow"][:16])
        lines = EXR_LINES.get(attrs["compression"][0])
        if lines is None:
            return  # a compression this check does not know: Blender decides
        chunks = math.ceil((ymax - ymin + 1) / lines)
        table_end = pos + 8 * chunks
        if chunks <= 0 or table_end > len(data):
            raise truncated
        for offset in struct.unpack_from(f"<{chunks}Q", data, pos):
            if offset < table_end or offset + 8 > len(data):
                raise truncated
            _, size = struct.unpack_from("<ii", data, offset)
            if size < 0 or offset + 8 + size > len(data):
                raise truncated
    except (IndexError, ValueError, struct.error):
        raise truncated from None
