"""The store's blobs: one file per key under ``blobs/<first two hex digits>/``, and the listings
of those folders that let a run check a million keys without a ``stat`` each."""

from __future__ import annotations

import os
import re
import time
from pathlib import Path
from typing import Iterable, NamedTuple

from sweep3d.cache import snapshot
from sweep3d.cache.files import scan, store_error
from sweep3d.cache.snapshot import StateSnapshot

#: Blobs a ``truths`` row owns beside its key (``blobs/ab/<truth_key>.<suffix>``) and the column
#: recording each one's SHA-256 (null: the pass was not rendered).
TRUTH_BLOBS = {"mask.png": "mask_sha256", "depth.npz": "depth_sha256"}
BLOB_TABLES = ("renders", "images")  # tables whose rows each own the blob named by their key
DIGEST_COLUMN = "sha256"  # hex SHA-256 of a blob's bytes, recorded in its row when written
BLOB_EXT = "png"  # the file type of the blobs a run makes
BLOB_SUFFIXES = (f".{BLOB_EXT}", *(f".{suffix}" for suffix in TRUTH_BLOBS))  # the names of blobs end so
_HEX = re.compile(r"[0-9a-f]+")  # a key, as :mod:`sweep3d.cache.hashing` writes it
FEW_KEYS = 1000  # up to this many keys are checked one by one: no listing is worth its set-up
LISTING_ADVANTAGE = 4  # listing a folder's entries costs about a quarter of a stat per entry
LISTING_SETTLED = 2.0  # seconds since a blob folder last changed before its listing is remembered


class BlobListing(NamedTuple):
    """What one blob folder holds: ``keys``, each of whose blob (``<key>.png``, the key
    beginning with the folder's name) is there, and the ``others``: every other name in it
    (a killed writer's temp file, a blob of another kind)."""

    keys: frozenset[str]
    others: frozenset[str]



class BlobFolders:
    """:class:`~sweep3d.cache.store.Store`'s blobs: their paths, and which keys' blobs are there."""

    root: Path
    _blobs: str  # blob_file's prefix, made once
    _listed: dict[str, tuple[tuple[int, ...], BlobListing]]  # blob folder -> (its state, listing)
    _joined: tuple[list[BlobListing], frozenset[str]] | None  # listings, their keys together
    state_snapshot: StateSnapshot | None  # every blob's file state, taken ahead (see snapshot_states)

    def blob_path(self, key: str, ext: str = "png") -> Path:
        return Path(self.blob_file(key, ext))

    def blob_file(self, key: str, ext: str = "png") -> str:
        """:meth:`blob_path` as a string: a run checks every cached blob, and pathlib's joins
        cost more than the ``stat`` itself."""
        return f"{self._blobs}{key[:2]}{os.sep}{key}.{ext}"

    def has_blob(self, key: str, ext: str = "png") -> bool:
        """Whether ``key``'s blob is there; a blob folder this process may not read is one line
        (:class:`StoreReadError`), never taken for a missing blob to be made again."""
        try:
            os.stat(self.blob_file(key, ext))
        except (FileNotFoundError, NotADirectoryError):
            return False
        except OSError as exc:
            raise store_error(exc, "read") from None
        return True

    def existing_blobs(self, keys: Iterable[str], ext: str = "png") -> set[str]:
        """The ``keys`` whose blob is there.

        Many keys are looked up in a listing of the blob folders: the snapshot's, where a run took
        one (:meth:`snapshot_states`), else :meth:`blob_listing`, which reads a name where a check
        per key costs a ``stat`` (about five times as much); few are checked one by one.
        """
        keys = keys if isinstance(keys, (set, frozenset)) else set(keys)
        if len(keys) <= FEW_KEYS:
            return {key for key in keys if os.path.exists(self.blob_file(key, ext))}
        taken = self.state_snapshot.read() if self.state_snapshot is not None and ext == BLOB_EXT else None
        if taken is not None:  # the child listed every blob folder while the run planned
            return keys & taken.key_set
        folders = sorted({key[:2] for key in keys})
        if sum(_folder_entries(self.root / "blobs" / f) for f in folders) > LISTING_ADVANTAGE * len(keys):
            return {key for key in keys if os.path.exists(self.blob_file(key, ext))}
        listings = [self.blob_listing(folder) for folder in folders]
        if ext != BLOB_EXT:  # a pass's blob: "<key>.mask.png" is listed as the blob key "<key>.mask"
            inner = f".{ext.removesuffix(f'.{BLOB_EXT}')}" if ext.endswith(f".{BLOB_EXT}") else None
            return keys & {key for folder, listing in zip(folders, listings)
                           for names, suffix in ((listing.others, f".{ext}"), (listing.keys, inner)) if suffix
                           for key in _split_listing(names, folder, suffix)[0]}
        joined = self._joined  # the same listings as last time: their keys joined then
        if joined is None or len(joined[0]) != len(listings) or any(a is not b for a, b in zip(joined[0], listings)):
            self._joined = joined = (listings, frozenset().union(*(listing.keys for listing in listings)))
        return keys & joined[1]

    def snapshot_states(self) -> None:
        """Start taking every blob's file state in a child process, when the store holds many
        (see :mod:`sweep3d.cache.snapshot`); call it holding the lock, and :meth:`forget_states`
        before anything writes a blob."""
        blobs = self.root / "blobs"
        if self.state_snapshot is not None or blobs.is_symlink() or not blobs.is_dir():
            return
        folders = [blobs / e.name for e in scan(blobs) if len(e.name) == 2]
        if sum(_folder_entries(folder) for folder in folders) >= snapshot.MIN_BLOBS:
            self.state_snapshot = snapshot.StateSnapshot(blobs)

    def forget_states(self) -> None:
        """Drop the snapshot of blob states (blobs are about to be written: it would go stale)."""
        taken, self.state_snapshot = self.state_snapshot, None
        if taken is not None:
            taken.close()

    def blob_others(self, folder: str) -> Iterable[str]:
        """What the blob folder ``blobs/<folder>`` holds besides blobs: from the snapshot's
        listing where a run took one (:meth:`snapshot_states`), else from :meth:`blob_listing`."""
        looked = self.state_snapshot.head() if self.state_snapshot is not None and len(folder) == 2 else None
        return looked[1].get(folder, ()) if looked is not None else self.blob_listing(folder).others

    def blob_listing(self, folder: str) -> BlobListing:
        """What the blob folder ``blobs/<folder>`` holds (nothing when it is not there).

        A run asks several times (the temp-file sweep, the warning before rendering, each
        stage's pass), so a listing is remembered while the folder stays the same: same inode,
        change and modification times. Adding, removing or renaming an entry moves a folder's
        times on, but only to the file system's clock tick: a listing is remembered only when
        the folder last changed a while (:data:`LISTING_SETTLED`) before it was taken, so a
        change in the same tick as an earlier one is never missed.
        """
        path = f"{self._blobs}{folder}"
        try:
            st = os.stat(path)
            state = (st.st_dev, st.st_ino, st.st_mtime_ns, st.st_ctime_ns, st.st_size)
            remembered = self._listed.get(folder)
            if remembered is not None and remembered[0] == state:
                return remembered[1]
            listed_at = time.time_ns()
            names = os.listdir(path)
        except FileNotFoundError:
            self._listed.pop(folder, None)
            return BlobListing(frozenset(), frozenset())
        except OSError as exc:
            raise store_error(exc, "read") from None
        keys, others = _split_listing(names, folder, f".{BLOB_EXT}")
        listing = BlobListing(frozenset(keys), frozenset(others))
        if listed_at - max(st.st_mtime_ns, st.st_ctime_ns) >= LISTING_SETTLED * 1e9:
            self._listed[folder] = (state, listing)
        else:
            self._listed.pop(folder, None)
        return listing


def blob_key(name: str, folder: str) -> str | None:
    """The key whose blob the file ``name`` in the blob folder ``folder`` is; None when the store
    gives no blob that name (``<key>.png``, ``<key>.mask.png``, ``<key>.depth.npz``: the key hex
    and beginning with the folder's name, as :meth:`Store.blob_file` places it)."""
    for suffix in BLOB_SUFFIXES:
        key = name[:-len(suffix)]
        if name.endswith(suffix) and key[:2] == folder and _HEX.fullmatch(key):
            return key
    return None


def _folder_entries(folder: Path) -> int:
    """About how many entries ``folder`` holds, from its size (no listing); 0 when it is not there."""
    try:
        return os.stat(folder).st_size // 32  # ext4: 8 bytes + a 44-character name per entry; tmpfs: 20
    except OSError:
        return 0


def _split_listing(names: Iterable[str], folder: str, suffix: str) -> tuple[list[str], list[str]]:
    """``names`` of the blob folder ``folder`` as (the keys whose blob they are, the rest): a
    blob is ``<key><suffix>``, its key beginning with the folder's name (as :meth:`Store.blob_file`
    places it)."""
    cut = -len(suffix)
    names = names if isinstance(names, list) else list(names)
    keys = [name[:cut] for name in names if name.endswith(suffix) and name[:cut][:2] == folder]
    if len(keys) == len(names):  # a blob folder holds blobs only, but for a killed writer's temp file
        return keys, []
    return keys, [name for name in names if not (name.endswith(suffix) and name[:cut][:2] == folder)]
