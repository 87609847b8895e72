"""The content-addressed store: blobs by key, append-only Parquet segments, DuckDB views.

Layout under the store root::

    blobs/ab/abcdef….png          one file per key (renders and post-processed images)
    blobs/ab/abcdef….mask.png     a truth key's object mask (and ``.depth.npz``, its depth)
    tables/<table>/<seg>.parquet  append-only row segments of each declared table (the pipeline's:
                                  renders, images, predictions, runs, parts, truths; and those other
                                  packages register, see :mod:`sweep3d.cache.contracts`)
    <folder>/<sha256><suffix>     files a declared table's rows name (its contract's kept files)
    jobs/<experiment>.parquet     the latest plan of each experiment (its jobs and their keys)
    lock                          held by the one process that writes

The store knows keys, files and their integrity, and what a table means only through its
contract (key, columns, which row of a key counts). :class:`Store` is split by role, each a
module of its own: :mod:`~sweep3d.cache.store_blobs` (the blobs and their listings),
:mod:`~sweep3d.cache.store_write` (atomic segment writes), :mod:`~sweep3d.cache.store_read`
(segments checked once, keys, the views), :mod:`~sweep3d.cache.store_repair` (damage control)
and :mod:`~sweep3d.cache.store_lock` (the writer lock); the whole-store commands are one module
each: :mod:`~sweep3d.cache.verification`, :mod:`~sweep3d.cache.repairs`,
:mod:`~sweep3d.cache.garbage`, :mod:`~sweep3d.cache.compaction` and :mod:`~sweep3d.cache.stats`.

Every write is a temp file plus an atomic rename, so a killed run leaves either a whole file
or none: rerunning recomputes only what no complete row records. Segments carry Parquet page
checksums; a segment that fails to read (corrupted on disk, or whose columns are not its
table's: lacking one it lists, or, listing none, one its table's rows always have) is skipped with
one warning, and moved to ``quarantine/`` when the process reading it
holds the writer lock (its rows are then recomputed), so a damaged store never crashes a run and
readers never change it. A full disk or a read-only folder is a :class:`StoreWriteError`, a
folder that cannot be read a :class:`StoreReadError` (one-line user errors); a failed write
leaves no temp file.
"""

from __future__ import annotations

import errno
import os
import uuid
from pathlib import Path

from sweep3d.cache.columns import COLUMNS_METADATA, check_column_list, lacking_columns, with_column_list
from sweep3d.cache.contracts import KEY_COLUMN, TABLES
from sweep3d.cache.files import (
    FIXES,
    FULL_ERRNOS,
    READ_ERRORS,
    STORE_FIX,
    WRITE_ERRNOS,
    StoreReadError,
    StoreWriteError,
    atomic_write,
    full_disk_error,
    is_full_disk,
    mount_point,
    read_parquet,
    safe_filename,
    scan,
    segment_name,
    store_error,
    utc_now,
)
from sweep3d.cache.query import is_select, lock_down
from sweep3d.cache.store_blobs import (
    BLOB_EXT,
    BLOB_SUFFIXES,
    BLOB_TABLES,
    DIGEST_COLUMN,
    TRUTH_BLOBS,
    BlobFolders,
    BlobListing,
    blob_key,
)
from sweep3d.cache.store_lock import WriterLock
from sweep3d.cache.store_read import SUPERSEDED_GRACE, SegmentReads
from sweep3d.cache.store_repair import DamageControl
from sweep3d.cache.store_write import SegmentWriter, SegmentWrites
from sweep3d.core import UserError

__all__ = [  # the names other modules have long imported from here
    "BLOB_EXT", "BLOB_SUFFIXES", "BLOB_TABLES", "COLUMNS_METADATA", "DIGEST_COLUMN", "FIXES", "FULL_ERRNOS",
    "KEY_COLUMN", "READ_ERRORS", "STORE_FIX", "SUPERSEDED_GRACE", "TABLES", "TRUTH_BLOBS", "WRITE_ERRNOS",
    "BlobListing", "SegmentWriter", "Store", "StoreReadError", "StoreWriteError", "atomic_write", "blob_key",
    "check_column_list", "full_disk_error", "is_full_disk", "is_select", "lacking_columns", "lock_down",
    "mount_point", "read_parquet", "safe_filename", "scan", "segment_name", "store_error", "utc_now",
    "with_column_list",
]


class Store(BlobFolders, SegmentWrites, SegmentReads, DamageControl, WriterLock):
    """A store rooted at ``root``; cheap to construct, creates directories on first write."""

    def __init__(self, root: str | Path, quarantine: bool = True, warn: bool = True) -> None:
        """Args:
            quarantine: move unreadable segments to ``quarantine/`` when a read finds them while
                this process holds the writer lock (:meth:`lock`); without it they are only
                skipped, as by every reader (False: never move them, as ``cache verify`` does).
            warn: log one warning per unreadable file (``cache verify`` lists them itself).
        """
        self.root = Path(root)
        self._blobs = f"{self.root}{os.sep}blobs{os.sep}"  # blob_file's prefix, made once
        self.quarantine_bad = quarantine
        self.warn = warn
        self._checked: dict[tuple[str, int, int], list[str]] = {}  # (path, size, mtime) read whole once -> columns
        self._unlisted: set[tuple[str, int, int]] = set()  # ... of those, the segments listing no columns
        self._condemned: set[tuple[str, int, int]] = set()  # segments require_columns found damaged
        self._bad: dict[str, str] = {}  # unreadable files already reported -> why
        self._keys: dict[str, tuple[tuple, frozenset[str]]] = {}  # table -> (segment state, its keys)
        self._listed: dict[str, tuple[tuple[int, ...], BlobListing]] = {}  # blob folder -> (its state, listing)
        self._joined: tuple[list[BlobListing], frozenset[str]] | None = None  # listings, their keys together
        self.state_snapshot = None  # every blob's file state, taken ahead (see snapshot_states)

    # -- paths -------------------------------------------------------------------------------
    def table_dir(self, table: str) -> Path:
        return self.root / "tables" / table

    def jobs_path(self, experiment: str) -> Path:
        return self.root / "jobs" / f"{safe_filename(experiment)}.parquet"

    def report_path(self, experiment: str, suffix: str = ".html", kind: str = "") -> Path:
        """Where an experiment's report files go by default: ``reports/<experiment><suffix>``, and
        another kind of output under its own folder, ``reports/<kind>/<experiment><suffix>``, so
        that no experiment's name can make it another's report (``q-bench`` and ``q``'s bench)."""
        folder = self.root / "reports" / kind if kind else self.root / "reports"
        return folder / f"{safe_filename(experiment)}{suffix}"

    def tmp_dir(self) -> Path:
        path = self.root / "tmp"
        path.mkdir(parents=True, exist_ok=True)
        return path

    def ensure_writable(self) -> None:
        """Create the store root or fail with a clear message (an unwritable store is a user error)."""
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            probe = self.root / f".probe-{os.getpid()}-{uuid.uuid4().hex[:8]}"  # a name of its own: two threads
            # of one process probing at once removed each other's, and the second was told the store is not writable
            probe.write_bytes(b"")
            probe.unlink()
        except OSError as exc:
            fix = "fix its permissions or " if exc.errno in (errno.EACCES, errno.EPERM) else ""
            raise UserError(
                f"store {self.root} is not writable ({exc.strerror}); {fix}set experiment.store to a writable folder"
            ) from None
