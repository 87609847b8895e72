"""Copies of archive members extracted under the store's ``assets/``, checked against their source.

A mesh inside a zip is extracted once into ``assets/<id>/`` (see :func:`sweep3d.assets.sources.materialise_mesh`)
and rendered from there, its render keys hashed from those files. What the extraction wrote is
recorded beside it in :data:`MANIFEST` (JSON): each file's SHA-256, taken as it was written, and
its file state when last checked (size, mtime, change time, inode); and the archive's members
(CRC and size) and file state. Before each use the copy is checked (:func:`stale`): a file whose
state moved is hashed again, so an edit in place is found even with its mtime restored (the change
time cannot be set back); one that no longer matches, a missing one, or an archive whose members
changed means extracting again. ``sweep3d cache verify`` hashes every file (:func:`check_folder`).
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from pathlib import Path
from typing import Any, Callable

from sweep3d.cache.store import StoreWriteError, atomic_write

ASSETS_FOLDER = "assets"
MANIFEST = ".complete"  # written last: a folder without it was never completely extracted
VERSION = 1


def read_manifest(folder: Path) -> dict[str, Any] | None:
    """The manifest of an extracted folder; None when there is none, or it does not read (an
    extraction from before manifests were kept, which wrote ``ok``, included)."""
    try:
        data = json.loads((folder / MANIFEST).read_bytes())
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("v") != VERSION or not isinstance(data.get("files"), dict):
        return None
    return data


def record(folder: Path, files: list[str], archive: str, source: dict[str, list[int]]) -> None:
    """Write the manifest of ``files`` (paths relative to ``folder``) just extracted from
    ``archive``, whose members are ``source`` (:func:`members`)."""
    entries = {rel: {"sha256": file_sha256(folder / rel), "state": file_state(folder / rel)} for rel in sorted(files)}
    _write(folder, {"v": VERSION, "archive": file_state(Path(archive)), "source": source, "files": entries})


def members(zf: zipfile.ZipFile, infos: list[zipfile.ZipInfo]) -> dict[str, list[int]]:
    """The archive's ``infos`` as the manifest records them: name → [CRC-32, size]."""
    return {info.filename: [info.CRC, info.file_size] for info in infos}


def stale(folder: Path, manifest: dict[str, Any] | None, archive: str,
          listed: Callable[[], dict[str, list[int]]]) -> str | None:
    """Whether the copy in ``folder`` must be extracted again: None when it is the archive's, ""
    when it has no manifest or the archive changed (nothing to warn of), else why it was damaged.

    Args:
        listed: called with no argument, the archive's members as :func:`members` gives them
            (read only when the archive's file state moved since the manifest was written).
    """
    if manifest is None:
        return ""
    changed = changed_files(folder, manifest)
    if changed:
        return (f"{', '.join(changed[:3])}{', …' if len(changed) > 3 else ''} "
                f"{'does' if len(changed) == 1 else 'do'} not match what was extracted")
    state = file_state(Path(archive))
    if state == manifest.get("archive"):
        return None
    if listed() != manifest.get("source"):
        return ""  # a new archive at the same path: its members are extracted
    manifest["archive"] = state
    _remember(folder, manifest)
    return None


def changed_files(folder: Path, manifest: dict[str, Any]) -> list[str]:
    """The extracted files that are missing or no longer match their recorded digest. A file whose
    state moved but whose bytes still match has its state refreshed in the manifest."""
    changed, refreshed = [], False
    for rel, entry in manifest["files"].items():
        path = folder / rel
        try:
            state = file_state(path)
            if state == entry.get("state"):
                continue
            if file_sha256(path) != entry.get("sha256"):
                changed.append(rel)
                continue
        except OSError:
            changed.append(rel)
            continue
        entry["state"], refreshed = state, True
    if refreshed and not changed:
        _remember(folder, manifest)
    return changed


def check_folder(folder: Path) -> list[tuple[str, str]]:
    """(file, why) for each file of an extracted folder that is missing or does not match its
    recorded digest, every file hashed (for ``cache verify``); [] for a folder without a manifest."""
    manifest = read_manifest(folder)
    if manifest is None:
        return []
    out = []
    for rel, entry in sorted(manifest["files"].items()):
        try:
            if file_sha256(folder / rel) != entry.get("sha256"):
                out.append((rel, "does not match the SHA-256 recorded when it was extracted"))
        except FileNotFoundError:
            out.append((rel, "missing: extracted, then deleted"))
        except OSError as exc:
            out.append((rel, exc.strerror or str(exc)))
    return out


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def file_state(path: Path) -> list[int]:
    """(size, mtime, change time, inode): an edit through the file system moves the change time on."""
    st = os.stat(path)
    return [st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino]


def _write(folder: Path, manifest: dict[str, Any]) -> None:
    atomic_write(folder / MANIFEST, json.dumps(manifest, sort_keys=True).encode(), durable=False)


def _remember(folder: Path, manifest: dict[str, Any]) -> None:
    """Write the manifest's refreshed file states where the store may be written: they only spare
    hashing next time (a read-only store hashes again), so a failure is no error."""
    try:
        _write(folder, manifest)
    except (OSError, StoreWriteError):
        pass
