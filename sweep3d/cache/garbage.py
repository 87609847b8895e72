"""``sweep3d cache gc`` and a run's sweep of killed writers' temp files: remove what no row
names and what no live writer is writing, and only files the store names so."""

from __future__ import annotations

import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

from sweep3d.cache.contracts import KeptFiles, table_contracts, table_names
from sweep3d.cache.files import StoreReadError, scan, store_files
from sweep3d.cache.store import Store
from sweep3d.cache.store_blobs import BLOB_TABLES, blob_key
from sweep3d.cache.verification import kept_names

TEMP_AGE = 3600.0  # seconds after which gc removes temp files (a live run's are younger)
#: Folders that only the writer lock's holder writes (``reports/`` and ``cache/`` are not:
#: ``sweep3d report`` writes them without the lock), besides the folders of the declared tables'
#: kept files (see :func:`locked_folders`).
LOCKED_FOLDERS = ("tables", "blobs", "jobs", "models", "outputs")
_HEX_NAME = re.compile(r"[0-9a-f]{64}")  # a kept file's name, less its suffix: the SHA-256 its row records
TEMP_PATTERN = ".*.tmp"  # how atomic_write names its temp files (a dot, the file's name, a tag, .tmp)


@dataclass
class Collected:
    blobs: int = 0
    temp_files: int = 0
    quarantined: int = 0
    bytes: int = 0
    kept: dict[KeptFiles, int] = field(default_factory=dict)  # a table's kept files -> how many no row names


def collect_garbage(root: Path, older_than: float = TEMP_AGE, purge_quarantine: bool = False) -> Collected:
    """Remove blobs that no row references, a table's kept files that none of its rows names, and
    temp files and segments a compaction replaced that are older than ``older_than`` seconds.

    Only what the store wrote goes: files named as it names blobs (:func:`blob_key`) and temp
    files (:data:`TEMP_PATTERN`); anything else put in its folders stays, and symbolic links are
    neither followed nor removed, so gc never reaches outside the store. Call it holding the
    writer lock (no run is writing). ``purge_quarantine`` also empties ``quarantine/``.

    Raises:
        StoreReadError: a segment or folder cannot be read: the blobs of its rows would look
            unreferenced, so nothing is removed.
    """
    store = Store(root)
    referenced: set[str] = set()
    for table in (*BLOB_TABLES, "truths"):  # a truth key owns its mask and depth blobs
        referenced |= store.keys(table)
    in_use = [(contract.kept, kept_names(store, contract)) for contract in table_contracts() if contract.kept is not None]
    _refuse_unread(store)
    out = Collected()
    now = time.time()

    def remove(entry: os.DirEntry) -> bool:
        try:
            size = entry.stat(follow_symlinks=False).st_size
            os.unlink(entry.path)
        except OSError:
            return False
        out.bytes += size
        return True

    def old(entry: os.DirEntry) -> bool:
        try:
            return now - entry.stat(follow_symlinks=False).st_mtime >= older_than
        except OSError:  # gone meanwhile
            return False

    blobs = root / "blobs"
    for folder, entry in _blob_files(blobs):
        if _is_temp(entry.name):
            out.temp_files += old(entry) and remove(entry)
        elif (key := blob_key(entry.name, folder)) is not None and key not in referenced:
            out.blobs += remove(entry)
    for kept, names in in_use:  # kept files no row names (files of other names are the user's, and stay)
        out.kept[kept] = 0
        for entry in store_files(root.joinpath(*kept.folder)):
            name = entry.name.removesuffix(kept.suffix)
            if _is_temp(entry.name):
                out.temp_files += old(entry) and remove(entry)
            elif entry.name.endswith(kept.suffix) and _HEX_NAME.fullmatch(name) and name not in names:
                out.kept[kept] += remove(entry)
    for table in table_names():
        out.temp_files += store.sweep_superseded(table, older_than)
    for folder in (root / "tables", root / "jobs", root / "reports"):
        out.temp_files += sum(old(e) and remove(e) for e in store_files(folder) if _is_temp(e.name))
    scratch = root / "tmp"
    out.temp_files += sum(old(e) and remove(e) for e in store_files(scratch))
    quarantine = root / "quarantine"
    if purge_quarantine:
        out.quarantined += sum(remove(e) for e in store_files(quarantine))
    for folder in (blobs, scratch, quarantine, *(root.joinpath(*kept.folder) for kept, _ in in_use)):
        _remove_empty_dirs(folder)
    return out


def _refuse_unread(store: Store) -> None:
    """Stop gc when a segment it read around is still there (one it may not read, a folder in
    its place): the blobs of its rows would look unreferenced."""
    left = [path for path in store.unreadable if os.path.lexists(path)]
    if left:
        where = Path(left[0]).relative_to(store.root)
        raise StoreReadError(f"gc removed nothing: {where} is unreadable ({store.unreadable[left[0]]}), so the "
                             "blobs of its rows would look unreferenced; fix it, or move it aside with sweep3d cache "
                             "verify --repair")


def _blob_files(blobs: Path) -> Iterator[tuple[str, os.DirEntry]]:
    """(blob folder's name, file) for every file directly in a blob folder (``blobs/ab/…``),
    without following symbolic links."""
    if blobs.is_symlink():
        return
    for folder in scan(blobs):
        if folder.is_dir(follow_symlinks=False):
            for entry in scan(Path(folder.path)):
                if entry.is_file(follow_symlinks=False):
                    yield folder.name, entry


def remove_killed_writers_temp_files(root: Path, store: Store | None = None) -> int:
    """Remove every temp file in the folders only the lock's holder writes; returns how many.

    Call it holding the writer lock, before writing: any temp file there then is a killed
    writer's (a live one would hold the lock), so unlike gc it need not wait for it to age.

    Args:
        store: the caller's store object: the blob folders are read through it
            (:meth:`Store.blob_others`): from the listing its snapshot took (a run over many
            blobs), else from its own listings, which it remembers for its existence checks, so
            a run lists its million blobs once.
    """
    store = store if store is not None else Store(root)
    removed = 0
    for name in locked_folders():
        folder = root / name
        found = _blob_temp_files(store) if name == "blobs" else (Path(e.path) for e in store_files(folder)
                                                                   if _is_temp(e.name))
        for path in found:
            try:
                path.unlink()
            except OSError:
                continue
            removed += 1
    return removed


def locked_folders() -> tuple[str, ...]:
    """The top-level folders only the writer lock's holder writes: :data:`LOCKED_FOLDERS` and
    those of the declared tables' kept files."""
    kept = (c.kept.folder[0] for c in table_contracts() if c.kept is not None)
    return tuple(dict.fromkeys((*LOCKED_FOLDERS, *kept)))


def _is_temp(name: str) -> bool:
    """Whether ``name`` matches :data:`TEMP_PATTERN`."""
    return len(name) >= 5 and name.startswith(".") and name.endswith(".tmp")


def _blob_temp_files(store: Store) -> Iterator[Path]:
    """What ``blobs/`` holds that matches :data:`TEMP_PATTERN`, at any depth (symbolic links
    neither followed nor listed), read from the store's listings of the blob folders: what a
    blob folder holds besides blobs (few names, if any) is looked at closer, and searched if it
    is a folder."""
    blobs = store.root / "blobs"
    if blobs.is_symlink():
        return
    for entry in scan(blobs):
        if entry.is_symlink():
            continue
        if _is_temp(entry.name) and entry.is_file():
            yield Path(entry.path)
        if not entry.is_dir():
            continue
        for name in store.blob_others(entry.name):
            path = blobs / entry.name / name
            if path.is_symlink():
                continue
            if _is_temp(name) and path.is_file():
                yield path
            if path.is_dir():
                yield from (Path(e.path) for e in store_files(path) if _is_temp(e.name))


def _remove_empty_dirs(folder: Path) -> None:
    """Remove the empty folders under ``folder`` and ``folder`` itself if it is left empty
    (symbolic links are not followed)."""
    if folder.is_symlink() or not folder.is_dir():
        return
    for path, _, _ in os.walk(folder, topdown=False):
        try:
            os.rmdir(path)
        except OSError:
            pass
