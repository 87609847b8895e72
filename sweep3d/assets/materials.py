"""An OBJ's materials checked when the spec loads: the MTL files its ``mtllib`` lines name, their
values (:mod:`.mtl_values`) and the texture files they name (:mod:`.texture_images`).

Both renderers take a missing MTL, a missing texture or a texture that is not an image without a
word (the object renders grey, or magenta), or fail every job at render time (Mitsuba). These
checks find each one before anything is planned and name the file and line to fix. A file is
looked for as the renderers look: beside the OBJ (an MTL) or the MTL (a texture), by the path as
written, with ``\\`` as ``/``, then by its bare name; for a mesh inside a zip, among the files
extracted with it (its own folder's, see ``sources.extracted_members``).

Errors: a missing or unreadable MTL; a number that is not one or not finite, a colour out of range;
a texture that is missing or not an image. Warnings (the run goes on): the same for what neither
renderer reads, ``Ka`` and the ``map_Ka``, ``disp`` (``map_Disp``) and ``decal`` textures.
"""

from __future__ import annotations

import os
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from sweep3d.assets.mtl_values import check_mtl_text
from sweep3d.assets.sniff import NOT_A_FILE, damaged_member, unreadable
from sweep3d.assets.texture_images import NotAnImage, file_format, image_format
from sweep3d.core import UserError

MTLLIB = re.compile(rb"(?m)^[ \t]*mtllib[ \t]+([^\r\n#]*)")
#: Texture statements of an MTL (lower case); those neither renderer reads are only warned about.
TEXTURE_KEYS = ("bump", "disp", "decal", "refl", "norm")
UNUSED_TEXTURES = ("map_ka", "disp", "map_disp", "decal", "map_decal")
#: A texture statement's options before its file, with how many values each takes (at most).
TEXTURE_OPTIONS = {"-o": 3, "-s": 3, "-t": 3, "-mm": 2, "-bm": 1, "-boost": 1, "-texres": 1, "-clamp": 1,
                   "-blendu": 1, "-blendv": 1, "-cc": 1, "-imfchan": 1, "-type": 1}


@dataclass
class MaterialAudit:
    """What the check found: warnings to print, and each base-colour texture (``map_Kd``) with its
    format, for an engine that reads only some formats (``stages.render.mitsuba.backend``)."""

    warnings: list[str] = field(default_factory=list)
    base_textures: list[tuple[str, str]] = field(default_factory=list)  # (where: "cube.mtl line 4", format)


def check_materials(ref: str) -> MaterialAudit:
    """Check the materials of a resolved mesh reference (a path, or ``archive.zip#member``); a mesh
    that is not an OBJ has none to check.

    Raises:
        UserError: naming the OBJ's or MTL's line to fix.
    """
    archive, sep, member = ref.partition("#")
    if Path(member if sep else archive).suffix.lower() != ".obj":
        return MaterialAudit()
    try:
        if sep:
            with zipfile.ZipFile(archive) as zf:
                return _audit(_ZipFolder(zf, Path(archive).name, member))
        return _audit(_DiskFolder(Path(archive)))
    except OSError as exc:
        raise unreadable(exc, "material file") from None


class _DiskFolder:
    """The files beside an OBJ on disk."""

    def __init__(self, obj: Path) -> None:
        self.obj, self.root = obj, obj.parent

    def obj_bytes(self) -> bytes:
        return self.obj.read_bytes()

    def find(self, name: str, near: str) -> str | None:
        """The path (relative to the OBJ's folder, or absolute) of the file ``name`` given in ``near``'s
        folder, or None when no candidate is a file (one that is something else is an error)."""
        base = PurePosixPath(near).parent
        for candidate in _candidates(name, base):
            path = Path(candidate) if Path(candidate).is_absolute() else self.root / candidate
            try:
                mode = path.stat().st_mode
            except (FileNotFoundError, NotADirectoryError):
                continue
            kind = next((kind for test, kind in NOT_A_FILE if test(mode)), None)
            if kind is not None:
                raise UserError(f"{candidate} is {kind}, not a file; give the path of a file")
            return candidate
        return None

    def read(self, name: str) -> bytes:
        return (Path(name) if Path(name).is_absolute() else self.root / name).read_bytes()

    def image_format(self, name: str) -> str:
        return file_format(Path(name) if Path(name).is_absolute() else self.root / name)

    def show(self, name: str) -> str:
        return name


class _ZipFolder:
    """The files extracted with an OBJ inside a zip (its folder's, not sub-folders')."""

    def __init__(self, zf: zipfile.ZipFile, archive: str, member: str) -> None:
        from sweep3d.assets.sources import extracted_members

        self.zf, self.archive, self.member = zf, archive, member
        self.folder = member.rsplit("/", 1)[0] + "/" if "/" in member else ""
        self.files = {info.filename[len(self.folder):] for info in extracted_members(zf, member)}

    def obj_bytes(self) -> bytes:
        return self.read(PurePosixPath(self.member).name)

    def find(self, name: str, near: str) -> str | None:
        base = PurePosixPath(near).parent
        return next((c for c in _candidates(name, base) if c in self.files), None)

    def read(self, name: str) -> bytes:
        try:
            return self.zf.read(self.folder + name)
        except (zipfile.BadZipFile, EOFError) as exc:
            raise damaged_member(self.show(name), exc) from None

    def image_format(self, name: str) -> str:
        return image_format(self.read(name))

    def show(self, name: str) -> str:
        return f"{self.archive}#{self.folder}{name}"


def _candidates(name: str, base: PurePosixPath) -> list[str]:
    """Where a renderer may find ``name`` written in a file of folder ``base``: as written, with
    ``\\`` as ``/``, then its bare name beside that file."""
    slashed = name.replace("\\", "/")
    out = []
    for written in (name, slashed):
        out.append(written if PurePosixPath(written).is_absolute() else os.path.normpath(base / written))
    out.append(str(base / PurePosixPath(slashed).name))
    return [c.removeprefix("./") for c in dict.fromkeys(out)]


def _audit(folder: _DiskFolder | _ZipFolder) -> MaterialAudit:
    audit = MaterialAudit()
    obj_name = PurePosixPath(folder.member).name if isinstance(folder, _ZipFolder) else folder.obj.name
    data = folder.obj_bytes()
    for match in MTLLIB.finditer(data):
        line = data.count(b"\n", 0, match.start()) + 1
        written = match.group(1).decode("utf-8", "replace").strip()
        where = f"{obj_name} line {line} ({('mtllib ' + written)[:60]!r})"
        try:
            libraries = _libraries(folder, written, obj_name)
        except UserError as exc:  # a folder or FIFO where the MTL should be
            raise UserError(f"{where}: {exc}") from None
        if libraries is None:
            raise UserError(f"{where}: {written} does not exist beside the OBJ, so every material of it would "
                            "render Blender's default grey; copy the MTL there or remove the mtllib line")
        for library in libraries:
            _audit_mtl(folder, library, audit)
    return audit


def _libraries(folder: _DiskFolder | _ZipFolder, written: str, obj_name: str) -> list[str] | None:
    """The MTL files an ``mtllib`` line names: the whole line as one path, else each word (several
    libraries on one line); None when neither is found."""
    whole = folder.find(written, obj_name)
    if whole is not None:
        return [whole]
    words = [folder.find(word, obj_name) for word in written.split()]
    return words if len(words) > 1 and None not in words else None  # type: ignore[return-value]


def _audit_mtl(folder: _DiskFolder | _ZipFolder, mtl: str, audit: MaterialAudit) -> None:
    data = folder.read(mtl)
    shown = folder.show(mtl)
    if b"\x00" in data[:1 << 16]:
        raise UserError(f"{shown} is not a text MTL file (it holds binary bytes); export the material again")
    text = data.decode("utf-8", "replace")
    for problem in check_mtl_text(text):
        if problem.fatal:
            raise UserError(problem.message(shown))
        audit.warnings.append(problem.message(shown))
    for number, raw in enumerate(text.splitlines(), 1):
        words = raw.split("#", 1)[0].split()
        if len(words) < 2 or not (words[0].lower().startswith("map_") or words[0].lower() in TEXTURE_KEYS):
            continue
        key, name = words[0], _texture_file(words[1:])
        where = f"{shown} line {number} ({raw.strip()[:60]!r})"
        fatal = key.lower() not in UNUSED_TEXTURES
        problem, fmt = _texture_problem(folder, name, mtl)
        if problem is None:
            if key.lower() == "map_kd":
                audit.base_textures.append((where, fmt))
            continue
        message = f"{where}: {problem}"
        if not fatal:
            audit.warnings.append(f"{message} (neither renderer reads {key}, so it is ignored)")
            continue
        raise UserError(message)


def _texture_problem(folder: _DiskFolder | _ZipFolder, name: str, mtl: str) -> tuple[str | None, str]:
    """(what is wrong with the texture ``name`` given in ``mtl``, or None; its format)."""
    if not name:
        return "no texture file is given; name one or remove the line", ""
    try:
        found = folder.find(name, mtl)
    except UserError as exc:  # a folder or FIFO where the texture should be
        return str(exc), ""
    if found is None:
        return (f"the texture {name} does not exist beside the MTL, so it would not render; copy it there or "
                "remove the line"), ""
    try:
        return None, folder.image_format(found)
    except NotAnImage as exc:
        return (f"the texture {folder.show(found)} is not a readable image ({exc}); save it again as PNG or "
                "JPEG"), ""
    except OSError as exc:
        raise unreadable(exc, "texture", folder.show(found)) from None


def _texture_file(words: list[str]) -> str:
    """The file of a texture statement's words, after its options (``-s 1 1 1``, ``-bm 0.5``, ...):
    the rest of the line, spaces included."""
    i = 0
    while i < len(words) and words[i].lower() in TEXTURE_OPTIONS and i + 1 < len(words):
        takes = TEXTURE_OPTIONS[words[i].lower()]
        i += 1
        taken = 0
        while taken < takes and i < len(words) - 1 and (taken == 0 or _is_number(words[i])):
            i += 1
            taken += 1
    return " ".join(words[i:])


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True
