"""Where meshes and HDRIs come from, and the content digests that go into render keys.

This module never imports bpy: the parent process resolves and hashes assets, the render
workers load them. A mesh reference is a path (relative to the spec file) or
``archive.zip#folder/model.obj`` for a model inside a zip (Sweet Home 3D's ``.sh3f``
furniture libraries are zips); the member's folder is extracted once into the store.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import re
import shutil
import zipfile
from functools import lru_cache
from importlib import metadata
from pathlib import Path

from sweep3d.assets.sniff import check_file, damaged_member, unreadable
from sweep3d.cache import ASSETS_FOLDER as EXTRACTED_FOLDER
from sweep3d.cache import MANIFEST as EXTRACTED_MANIFEST
from sweep3d.cache import digest, files_digest, full_disk_error, is_full_disk, read_manifest, stale
from sweep3d.cache import members as extracted_files
from sweep3d.cache import record as record_extracted
from sweep3d.core import UserError

MESH_SUFFIXES = {".obj", ".gltf", ".glb", ".ply", ".stl"}
HDRI_SUFFIXES = {".exr", ".hdr", ".png", ".jpg", ".jpeg", ".tif", ".tiff"}

log = logging.getLogger("sweep3d.store")


@lru_cache(maxsize=1)
def bpy_root() -> Path:
    """The bpy wheel's versioned data folder, found without importing bpy."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise UserError("bpy is not installed; run: pip install 'bpy==4.5.15'")
    package = Path(spec.origin).parent
    versions = sorted(p for p in package.iterdir() if re.fullmatch(r"\d+\.\d+", p.name))
    if not versions:
        raise UserError(f"cannot find Blender's data files under {package}; reinstall bpy")
    return versions[-1]


def builtin_hdris() -> dict[str, Path]:
    """The CC0 studio-light HDRIs that ship inside the bpy wheel, by name."""
    folder = bpy_root() / "datafiles" / "studiolights" / "world"
    return {p.stem: p for p in sorted(folder.glob("*.exr"))}


def blender_version() -> str:
    return metadata.version("bpy")


def resolve_hdri(ref: str, base: Path) -> str:
    """An HDRI reference (``builtin:NAME`` or a path) as an absolute path that exists."""
    check_named(ref, "HDRI", "an .exr or .hdr image, or builtin:NAME")
    if ref.startswith("builtin:"):
        name = ref.removeprefix("builtin:")
        maps = builtin_hdris()
        if name not in maps:
            raise UserError(f"no built-in HDRI {name!r}; valid: {', '.join('builtin:' + n for n in maps)}")
        return str(maps[name])
    path = Path(ref).expanduser()
    path = path if path.is_absolute() else base / path
    check_file(path, "HDRI file", "give a path relative to the spec, or builtin:NAME")
    if path.suffix.lower() not in HDRI_SUFFIXES:
        raise UserError(f"{path.name!r} is not an image Blender reads as an HDRI ({', '.join(sorted(HDRI_SUFFIXES))})")
    return str(path.resolve())


def resolve_mesh(ref: str, base: Path) -> str:
    """A mesh reference with its path made absolute; checks that the file (or zip member) exists."""
    archive, sep, member = ref.partition("#")
    check_named(archive, "mesh", "a mesh file (or archive.zip#member.obj)")
    path = Path(archive).expanduser()
    path = path if path.is_absolute() else base / path
    check_file(path, "mesh file", "give a path relative to the spec file")
    suffix = Path(member if sep else archive).suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise UserError(f"unsupported mesh format {suffix or '(none)'!r}; use one of {', '.join(sorted(MESH_SUFFIXES))}")
    if sep:
        try:
            with zipfile.ZipFile(path) as zf:
                if member not in zf.namelist():
                    raise UserError(f"{path.name} has no member {member!r}")
        except zipfile.BadZipFile:
            raise UserError(f"{str(path)!r} is not a zip archive, so '#member' cannot be read from it") from None
        except OSError as exc:
            raise unreadable(exc, "mesh archive", path) from None
        return f"{path.resolve()}#{member}"
    return str(path.resolve())


def check_named(ref: str, what: str, example: str) -> None:
    """Refuse an empty path: joined to the spec's folder it would name that folder ("is a directory")."""
    if not ref.strip():
        raise UserError(f"the {what} path is empty; give the path of {example}, relative to the spec file")


def materialise_mesh(ref: str, scratch: Path) -> Path:
    """A local file path for a mesh reference, extracting zip members' folders under ``scratch``.

    The extracted copy is checked against what was extracted before each use (see
    :mod:`sweep3d.cache.extracted`): a copy edited since, or one of an archive that changed, is
    extracted again (the first with a warning), so that what renders, and what its keys hash, is
    the archive's."""
    archive, sep, member = ref.partition("#")
    if not sep:
        return Path(archive)
    target = scratch / EXTRACTED_FOLDER / digest([archive, member])[:16]
    try:
        why = stale(target, read_manifest(target), archive, lambda: _members(archive, member))
        if why is not None:
            if why:
                log.warning(f"warning: the copy of {Path(archive).name}#{member} extracted under the store's "
                            f"{_relative(target, scratch)} was changed since ({why}); extracting it again")
            (target / EXTRACTED_MANIFEST).unlink(missing_ok=True)
            files = _extract(archive, member, target)
            record_extracted(target, files, archive, _members(archive, member))
    except OSError as exc:
        if is_full_disk(exc):  # a write's error names no file: it is the store's disk, not the archive
            shutil.rmtree(target, ignore_errors=True)  # what was extracted: the space back, none half done
            raise full_disk_error(exc, f"extract {Path(archive).name}#{member} into {target}", target) from None
        if not str(exc.filename or "").startswith(str(scratch)):
            raise  # reading the archive: the caller names the file
        raise UserError(f"cannot extract {member} into {str(target)!r}: {exc.strerror}; the store must be "
                        "writable") from None
    return target / member


def _members(archive: str, member: str) -> dict[str, list[int]]:
    """The archive's files that :func:`materialise_mesh` extracts for ``member``, with their CRCs and sizes."""
    with zipfile.ZipFile(archive) as zf:
        return extracted_files(zf, extracted_members(zf, member))


def _relative(path: Path, root: Path) -> str:
    return str(path.relative_to(root)) if path.is_relative_to(root) else str(path)


def extracted_members(zf: zipfile.ZipFile, member: str) -> list[zipfile.ZipInfo]:
    """The files :func:`materialise_mesh` extracts for ``member``: those of its folder (its
    materials and textures), not of sub-folders."""
    folder = member.rsplit("/", 1)[0] + "/" if "/" in member else ""
    return [info for info in zf.infolist() if info.filename.startswith(folder) and not info.is_dir()
            and info.filename.count("/") == member.count("/")]


def check_archive(ref: str, limit_mb: float) -> None:
    """Refuse a mesh archive one of whose extracted files declares more than ``limit_mb`` megabytes.

    Raises:
        UserError: naming the archive, the file, its size and ``[experiment] max_archive_mb``.
    """
    archive, sep, member = ref.partition("#")
    if not sep:
        return
    with zipfile.ZipFile(archive) as zf:
        for info in extracted_members(zf, member):
            if info.file_size > limit_mb * 1e6:
                raise UserError(f"{Path(archive).name}#{info.filename} expands to {info.file_size / 1e6:,.1f} MB "
                                f"({info.compress_size / 1e6:,.3g} MB zipped), over [experiment] max_archive_mb = "
                                f"{limit_mb:g}; raise max_archive_mb if the archive is trusted")


def _extract(archive: str, member: str, target: Path) -> list[str]:
    """Extract ``member``'s folder (its materials and textures) from ``archive`` into ``target``,
    each file no longer than it declares (the spec's check read those sizes, not the bytes), over
    whatever is there. Returns the files written, relative to ``target``."""
    written = []
    with zipfile.ZipFile(archive) as zf:
        for info in extracted_members(zf, member):
            path = target.joinpath(*(part for part in info.filename.split("/") if part not in ("", ".", "..")))
            path.parent.mkdir(parents=True, exist_ok=True)
            name = f"{Path(archive).name}#{info.filename}"
            try:
                with zf.open(info) as source, open(path, "wb") as out:
                    _copy_at_most(source, out, info.file_size, name)
            except zipfile.BadZipFile as exc:
                raise damaged_member(name, exc) from None
            written.append(path.relative_to(target).as_posix())
    return written


def _copy_at_most(source, out, size: int, name: str) -> None:
    """Copy ``source`` to ``out``, refusing it once it yields more than ``size`` bytes."""
    written = 0
    while chunk := source.read(1 << 20):
        written += len(chunk)
        if written > size:
            raise UserError(f"{name} expands to more than the {size:,} bytes its archive declares (a damaged or "
                            "crafted zip); repack the archive")
        out.write(chunk)


def mesh_files(path: Path) -> list[Path]:
    """The mesh file and the files it references (MTL libraries, textures, glTF buffers)."""
    files = [path]
    folder = path.parent
    suffix = path.suffix.lower()
    if suffix == ".obj":
        for mtl in _referenced(path, r"^\s*mtllib\s+(.+?)\s*$"):
            mtl_path = folder / mtl
            if mtl_path.is_file():
                files.append(mtl_path)
                files += [folder / t for t in _referenced(mtl_path, r"^\s*map_\w+\s+(?:-\S+\s+\S+\s+)*(.+?)\s*$")]
    elif suffix == ".gltf":
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            doc = {}
        for item in doc.get("buffers", []) + doc.get("images", []):
            uri = item.get("uri", "")
            if uri and not uri.startswith("data:"):
                files.append(folder / uri)
    return [f for f in dict.fromkeys(files) if f.is_file()]


def _referenced(path: Path, pattern: str) -> list[str]:
    regex = re.compile(pattern)
    out = []
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            m = regex.match(line)
            if m:
                out.append(m.group(1).strip().replace("\\", "/"))
    return out


def mesh_digest(ref: str, scratch: Path) -> str:
    """Content digest of a mesh and everything it references.

    Raises:
        UserError: one of those files cannot be read, or a zip member cannot be extracted.
    """
    try:
        return files_digest(mesh_files(materialise_mesh(ref, scratch)))
    except OSError as exc:
        raise unreadable(exc, "the mesh's file") from None
