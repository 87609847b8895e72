"""Cheap checks that a mesh or HDRI file is what its name says, before Blender sees it.

Blender imports a random-bytes OBJ as "no mesh", a vertex-only OBJ as an empty picture, and
loads a truncated or non-image HDRI as a magenta "missing texture" world without any error.
These checks read the file's header and structure, its vertex coordinates (``vertices``: NaN or
infinite ones) and an HDRI's pixels (``radiance``: a map with no light), never building
geometry, so a broken asset fails at spec load with a one-line error instead of rendering
garbage. They never open what is not a regular file (a FIFO would block, /dev/zero never ends).
They are conservative: a file they cannot judge (a multi-part or tiled EXR) passes, and
Blender's own errors in the render worker still become one-line user errors.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
import struct
import zipfile
from functools import lru_cache
from pathlib import Path

from sweep3d.assets import radiance, vertices
from sweep3d.assets.obj_faces import check_obj_geometry
from sweep3d.core import UserError

EXR_MAGIC = b"\x76\x2f\x31\x01"
#: Scanlines per chunk for each OpenEXR compression (NONE, RLE, ZIPS, ZIP, PIZ, PXR24, B44, B44A, DWAA, DWAB).
EXR_LINES = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32, 5: 16, 6: 32, 7: 32, 8: 32, 9: 256}


#: What a path is when it is not a regular file, by ``stat`` file type.
NOT_A_FILE = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a device file"),
              (stat.S_ISBLK, "a device file"), (stat.S_ISSOCK, "a socket"))


def not_a_file(path: str | Path) -> str | None:
    """What ``path`` is when it is there but is not a regular file ("a FIFO (named pipe)", "a
    directory"...), None otherwise (a file, or nothing there: the reader says so). Only ``stat``:
    opening a FIFO to see would wait for a writer for ever."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    return next((name for test, name in NOT_A_FILE if test(mode)), None)


def check_file(path: Path, what: str, missing: str) -> None:
    """Check that ``path`` is a regular file this process may read, saying what it is otherwise.

    Only ``stat`` and an open that reads nothing: a FIFO is never opened (that would block) and a
    device like /dev/zero never read (it never ends).

    Args:
        what: what the file is for, as the message starts ("mesh file").
        missing: the fix to suggest when nothing is there.

    Raises:
        UserError: it does not exist, is a directory, FIFO, device or socket, or is unreadable.
    """
    try:
        mode = path.stat().st_mode
    except (FileNotFoundError, NotADirectoryError):
        raise UserError(f"{what} {str(path)!r} does not exist; {missing}") from None
    except PermissionError:
        raise UserError(f"cannot reach {what} {str(path)!r}: permission denied on a folder of its path; make its "
                        f"folders searchable by this user, e.g. chmod a+x {str(path.parent)!r}") from None
    except OSError as exc:
        raise unreadable(exc, what, path) from None
    kind = next((name for test, name in NOT_A_FILE if test(mode)), None)
    if kind is not None:
        raise UserError(f"{what} {str(path)!r} is {kind}, not a file; give the path of a file")
    try:
        with open(path, "rb"):
            pass
    except OSError as exc:
        raise unreadable(exc, what, path) from None


def unreadable(exc: OSError, what: str, path: str | Path | None = None) -> UserError:
    """One line for a file the OS will not let us read (permission denied, an I/O error)."""
    name = str(exc.filename or path or "")
    if isinstance(exc, PermissionError):
        return UserError(f"cannot read {what} {name!r}: permission denied; make it (and its folders) readable "
                         f"by this user, e.g. chmod a+r {name!r}")
    return UserError(f"cannot read {what} {name!r}: {exc.strerror or exc}")


def check_mesh(ref: str) -> None:
    """Check a resolved mesh reference (a path, or ``archive.zip#member``).

    Raises:
        UserError: the file is empty, binary where text is expected, has no faces, or its
            header or size contradicts its format.
    """
    archive, sep, member = ref.partition("#")
    try:
        info = os.stat(archive)
        _check_mesh(archive, member if sep else "", info.st_size, info.st_mtime_ns)
    except OSError as exc:
        raise unreadable(exc, "mesh file", archive) from None


def check_hdri(path: str, pixels: bool = True) -> str | None:
    """Check that an HDRI file holds an image of the format its name says, is complete, and
    (with ``pixels``) holds light.

    Returns:
        A warning for a map that renders but looks wrong (some negative pixels), or None.

    Raises:
        UserError: the file is empty, not an image of that format, truncated, or all black.
    """
    try:
        info = os.stat(path)
        return _check_hdri(path, info.st_size, info.st_mtime_ns, pixels)
    except OSError as exc:
        raise unreadable(exc, "HDRI file", path) from None


def damaged_member(name: str, exc: Exception) -> UserError:
    """One line for an archive member that cannot be decompressed (a bad CRC, a size that lies)."""
    return UserError(f"{name} cannot be read from its archive ({exc}): a damaged or crafted zip; repack the archive")


@lru_cache(maxsize=256)
def _check_mesh(archive: str, member: str, size: int, mtime_ns: int) -> None:
    if member:
        with zipfile.ZipFile(archive) as zf:
            try:
                data = zf.read(member)
            except (zipfile.BadZipFile, EOFError) as exc:
                raise damaged_member(f"{Path(archive).name}#{member}", exc) from None
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
    vertices.check_obj(data)
    check_obj_geometry(data)


def _ply(data: bytes) -> None:
    end = data.find(b"end_header", 0, 1 << 16)
    if not data.startswith(b"ply") or end < 0:
        raise UserError("not a PLY file (no 'ply' ... 'end_header' header); export the mesh again")
    header = data[:end].decode("ascii", errors="replace").split("\n")
    fmt = next((line.split()[1] for line in header if line.startswith("format ") and len(line.split()) > 1), "")
    counts: dict[str, int] = {}
    props: dict[str, list[tuple[str, str]]] = {}  # element -> (type, name) of each property
    element = None
    for line in header:
        words = line.split()
        if len(words) >= 3 and words[0] == "element":
            element = words[1]
            counts[element] = int(words[2]) if words[2].isdigit() else -1
            props[element] = []
        elif len(words) >= 3 and words[0] == "property" and element is not None:
            props[element].append((words[1], words[-1]))
    if counts.get("vertex", 0) <= 0:
        raise UserError("the PLY file declares no vertices; export the mesh again")
    if counts.get("face", 0) <= 0:
        raise UserError("the PLY file has no faces (a point cloud), so nothing would be rendered; export it with faces")
    if fmt.startswith("binary"):
        sizes = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
                 "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}
        vertex = [kind for kind, _ in props.get("vertex", [])]
        if vertex and all(p in sizes for p in vertex):
            body = len(data) - data.find(b"\n", end) - 1
            needed = counts["vertex"] * sum(sizes[p] for p in vertex)
            if body < needed:
                raise UserError(f"the PLY file is truncated ({body} bytes of data, its {counts['vertex']} vertices "
                                f"need {needed}); copy or export it again")
    vertices.check_ply(data, data.find(b"\n", end) + 1, fmt, [(e, counts[e], props[e]) for e in counts])


def _stl(data: bytes) -> None:
    if len(data) >= 84:
        (triangles,) = struct.unpack_from("<I", data, 80)
        if triangles > 0 and len(data) == 84 + 50 * triangles:
            vertices.check_stl(data, binary=True)
            return
    head = data[:1 << 16].lstrip().lower()
    if head.startswith(b"solid") and b"facet" in head and b"vertex" in head:
        vertices.check_stl(data, binary=False)
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
    vertices.check_glb(data)


def _gltf(data: bytes) -> None:
    try:
        doc = json.loads(data)
    except (ValueError, UnicodeDecodeError) as exc:
        raise UserError(f"not glTF JSON ({str(exc).splitlines()[0]}); export the mesh as .gltf or .glb again") from None
    if not isinstance(doc, dict) or "asset" not in doc:
        raise UserError("not a glTF document (no 'asset' entry); export the mesh as .gltf or .glb again")


@lru_cache(maxsize=64)
def _check_hdri(path: str, size: int, mtime_ns: int, pixels: bool) -> str | None:
    suffix = Path(path).suffix.lower()
    with open(path, "rb") as fh:
        data = fh.read()
    if not data:
        raise UserError("the HDRI file is empty; give an .exr or .hdr image")
    if suffix == ".exr":
        layout = _exr(data)
        return radiance.check_exr(data, *layout) if pixels and layout else None
    if suffix == ".hdr":
        if not (data.startswith(b"#?RADIANCE") or data.startswith(b"#?RGBE")):
            raise UserError("not a Radiance .hdr image (no '#?RADIANCE' header); give an .exr or .hdr image")
        if not re.search(rb"\n\n[-+][YX] \d+ [-+][XY] \d+\n.", data[:1 << 16], re.S):
            raise UserError("the .hdr image has no resolution line or no pixels (truncated?); save it again")
        if pixels:
            radiance.check_hdr(data)
    elif suffix in (".png", ".jpg", ".jpeg", ".tif", ".tiff"):
        _pil_image(path, pixels)
    return None


def _pil_image(path: str, pixels: bool) -> None:
    from PIL import Image

    try:
        with Image.open(path) as img:
            img.verify()
        if pixels:
            with Image.open(path) as img:
                light = _brightest(img)
    except Exception as exc:  # noqa: BLE001  (any decoder complaint means a broken image)
        raise UserError(f"not a readable image ({exc}); save it again as .exr or .hdr") from None
    if pixels and light <= 0:
        raise UserError("the image is black (every pixel is 0), so it would light nothing and every render "
                        "would be black; give a map with light in it")


def _brightest(img) -> float:
    """The largest colour value of a Pillow image (alpha left out; palette, CMYK, ... as RGB)."""
    if img.mode not in ("L", "LA", "RGB", "RGBA", "I", "F", "I;16"):
        img = img.convert("RGB")
    extrema = img.getextrema()
    bands = img.getbands()
    per_band = extrema if len(bands) > 1 else [extrema]
    return max(high for (_, high), name in zip(per_band, bands) if name != "A")


def _exr(data: bytes) -> tuple[dict[str, bytes], tuple[int, ...]] | None:
    """OpenEXR: magic, then for single-part scanline files, a complete chunk offset table.

    Returns:
        The header's attributes and the chunks' offsets, or None for a layout left to Blender.
    """
    if data[:4] != EXR_MAGIC:
        raise UserError("not an OpenEXR image (no EXR magic number); give an .exr or .hdr image")
    flags = struct.unpack_from("<I", data, 4)[0] >> 8
    if flags & (0x2 | 0x8 | 0x10):  # tiled, deep or multi-part: leave those to Blender
        return None
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
            return None  # a compression this check does not know: Blender decides
        chunks = math.ceil((ymax - ymin + 1) / lines)
        table_end = pos + 8 * chunks
        if chunks <= 0 or table_end > len(data):
            raise truncated
        offsets = struct.unpack_from(f"<{chunks}Q", data, pos)
        for offset in offsets:
            if offset < table_end or offset + 8 > len(data):
                raise truncated
            _, size = struct.unpack_from("<ii", data, offset)
            if size < 0 or offset + 8 + size > len(data):
                raise truncated
    except (IndexError, ValueError, struct.error):
        raise truncated from None
    return attrs, offsets
