"""The content-addressed store: blobs by key, append-only Parquet segments, DuckDB views.

Layout under the store root::

    blobs/ab/abcdef….png          one file per key (renders and post-processed images)
    blobs/ab/abcdef….mask.png     a truth key's object mask (and ``.depth.npz``, its depth)
    tables/<table>/<seg>.parquet  append-only row segments (renders, images, predictions, runs, parts, truths,
                                  stability, verdicts)
    realism/photos/<sha256>.jpg   the photographs ``realism score`` scored, as the model saw them
    jobs/<experiment>.parquet     the latest plan of each experiment (its jobs and their keys)
    lock                          held by the one process that writes

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
import fcntl
import hashlib
import json
import logging
import os
import re
import shutil
import stat
import threading
import time
import uuid
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Collection, Iterable, Iterator, NamedTuple

import duckdb
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from sweep3d.cache import snapshot
from sweep3d.cache.snapshot import StateSnapshot
from sweep3d.core import StoreBusyError, UserError

TABLES = ("renders", "images", "predictions", "runs", "parts", "truths", "stability", "verdicts")
KEY_COLUMN = {"renders": "render_key", "images": "image_key", "predictions": "pred_key", "runs": "run_id",
              "parts": "parts_key", "truths": "truth_key", "stability": "stability_key", "verdicts": "verdict_key"}
#: Tables whose newest row of a key is the one that counts: a verdict of a job scored again
#: (``sweep3d realism score``) replaces the earlier one. In every other table a key names its
#: inputs, so its rows are alike and the first one counts.
NEWEST_WINS = frozenset({"verdicts"})
#: Where ``realism score`` keeps each photograph it scored (framed as its render, a small JPEG
#: named by the SHA-256 of the photograph's file, recorded in its verdicts' ``photo_sha256``).
PHOTOS_FOLDER = ("realism", "photos")
#: Where ``realism pick`` writes an experiment's kit by default (``kits/<experiment>``): the one
#: folder of the store that is the user's to read and add photographs to, not a run's.
KITS_FOLDER = "kits"
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
SUPERSEDED_GRACE = 600.0  # seconds a compaction keeps the segments it merged, for readers that listed them

#: Write failures the user can fix (free space, permissions, a folder where a file should be),
#: reported as one line, not a traceback.
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EISDIR,
                          errno.ENOTDIR})
#: How to fix what an errno says about a path of the store (permissions, a misplaced file or folder).
FIXES = {errno.EACCES: "fix its permissions", errno.EPERM: "fix its permissions",
         errno.EISDIR: "a folder is where the store keeps a file: move it away",
         errno.ENOTDIR: "a file is where the store keeps a folder: move it away"}
#: What reading a damaged Parquet file raises (pyarrow's ArrowInvalid is a ValueError).
READ_ERRORS = (OSError, ValueError, pa.ArrowException)
#: Parquet metadata key of a segment listing the columns it was written with (a JSON list).
COLUMNS_METADATA = b"sweep3d.columns"

#: Columns a file of each table must have (its key), and a jobs file (what results join on).
REQUIRED_COLUMNS = {**{table: (key,) for table, key in KEY_COLUMN.items()}, "jobs": ("pred_key",)}
#: Columns every segment of each table has had since sweep3d first wrote it: its stage's schema less
#: the columns added since (a blob's ``sha256``, a truth's ``framed_pixels``: older segments rightly
#: lack them). A segment that lists no columns of its own (written before segments did, or rewritten
#: by a tool that dropped the list) is judged by these instead: lacking one, it was rewritten without
#: it, and is damaged, not rows of NULLs. A prediction's evaluator columns depend on its evaluator:
#: see :meth:`Store.require_columns`.
TABLE_COLUMNS = {
    "renders": ("render_key", "width", "height", "valid", "seconds", "created_at"),
    "images": ("image_key", "render_key", "valid", "seconds", "created_at"),
    "predictions": ("pred_key", "image_key", "model", "model_digest", "seconds", "created_at"),
    "runs": ("run_id", "experiment", "spec_path", "spec", "jobs", "started_at", "created_at", "seconds"),
    "parts": ("parts_key", "render_key", "layout", "parts", "pixels", "object_pixels", "created_at"),
    "truths": ("truth_key", "render_key", "passes", "gt_x0", "gt_y0", "gt_x1", "gt_y1", "visible_pixels",
               "silhouette_pixels", "visible_fraction", "silhouette", "truth_seconds", "mask_sha256", "depth_sha256",
               "created_at"),
    "stability": ("stability_key", "pred_key", "image_key", "change", "base_correct", "base_margin", "correct",
                  "margin", "flipped", "created_at"),
    "verdicts": ("verdict_key", "source", "experiment", "job", "model", "valid", "correct", "created_at"),
}

log = logging.getLogger("sweep3d.store")
MAX_FILENAME_BYTES = 120  # of an experiment's name in file names: with suffixes, well under 255
#: Stores whose writer lock this process holds (by real path), and the thread that took it: only
#: their holder quarantines, and that thread may take the lock again within (see :meth:`Store.lock`).
_HELD: dict[str, int] = {}


class StoreWriteError(UserError):
    """The store cannot be written: a full disk, a quota, a read-only or forbidden folder."""


class StoreReadError(UserError):
    """A folder or file of the store cannot be read (its permissions), or is not what the store
    keeps there (a file where a folder should be)."""


class BlobListing(NamedTuple):
    """What one blob folder holds: ``keys``, each of whose blob (``<key>.png``, the key
    beginning with the folder's name) is there, and the ``others``: every other name in it
    (a killed writer's temp file, a blob of another kind)."""

    keys: frozenset[str]
    others: frozenset[str]


class Store:
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
        self.state_snapshot: StateSnapshot | None = None  # every blob's file state, taken ahead (see snapshot_states)

    # -- paths -------------------------------------------------------------------------------
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
        taken = self.state_snapshot.read() if self.state_snapshot is not None and len(folder) == 2 else None
        return taken.others.get(folder, ()) if taken is not None else self.blob_listing(folder).others

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

    # -- writes ------------------------------------------------------------------------------
    def write_table_file(self, path: Path, table: pa.Table, keep_same: bool = False) -> bool:
        """Write ``table`` to ``path`` atomically (temp file, fsync, rename), with page checksums.

        Args:
            keep_same: leave ``path`` alone when it holds exactly the bytes it would be written
                with (a run writes its unchanged plan again: the file then keeps its state, which
                :func:`~sweep3d.results.stored_summary` keys on).

        Returns:
            whether ``path`` was written.

        Raises:
            StoreWriteError: the disk is full or the folder is not writable (no temp file is left).
        """
        if keep_same:
            sink = pa.BufferOutputStream()
            pq.write_table(table, sink, compression="zstd", write_page_checksum=True)
            data = sink.getvalue()
            if _holds(path, data):
                return False
            atomic_write(path, data)  # type: ignore[arg-type]  (a pyarrow Buffer is bytes-like)
            return True
        tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            pq.write_table(table, tmp, compression="zstd", write_page_checksum=True)
            with open(tmp, "rb") as fh:
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        except BaseException as exc:
            _unlink_quietly(tmp)
            if _is_write_error(exc):
                raise _as_write_error(exc, path) from None
            raise
        return True

    def append(self, table: str, rows: list[dict[str, Any]], schema: pa.Schema | None = None) -> Path | None:
        """Write ``rows`` as one new segment of ``table``; returns its path (None if no rows)."""
        if not rows:
            return None
        data = with_column_list(pa.Table.from_pylist(rows, schema=schema))
        path = self.table_dir(table) / segment_name()
        self.write_table_file(path, data)
        return path

    def segment_writer(self, table: str, schema: pa.Schema | None = None, every: float = 3.0,
                       max_rows: int = 64) -> "SegmentWriter":
        return SegmentWriter(self, table, schema, every, max_rows)

    # -- reads -------------------------------------------------------------------------------
    def segments(self, table: str) -> list[Path]:
        """The segment files of ``table`` in write order.

        Temp files are never listed, nor segments a compaction has merged into one that exists
        (they stay on disk a while for readers that listed them before; see :meth:`superseded`).
        """
        names = [entry.name for entry in scan(self.table_dir(table))]
        merged = {name for _, replaced, _ in self.superseded(table, names) for name in replaced}
        return sorted(self.table_dir(table) / name for name in names if _is_segment_name(name) and name not in merged)

    def superseded(self, table: str, names: list[str] | None = None) -> list[tuple[Path, list[str], float]]:
        """Compactions of ``table`` whose merged segment exists: (record, segment names it
        replaces, when). The replaced files are deleted by :meth:`sweep_superseded` after a grace
        period, so a query that listed them just before the compaction can still open them.

        Args:
            names: what the table's folder holds, when the caller has just listed it.
        """
        out = []
        names = [entry.name for entry in scan(self.table_dir(table))] if names is None else names
        for record in sorted(self.table_dir(table) / n for n in names if n.startswith(".compacted-")
                             and n.endswith(".json")):
            try:
                entry = json.loads(record.read_text())
            except (OSError, ValueError):
                continue
            if (self.table_dir(table) / entry.get("merged", "")).is_file():
                replaced = [n for n in entry.get("replaces", []) if isinstance(n, str) and _is_segment_name(n)]
                out.append((record, replaced, float(entry.get("at", 0.0))))
        return out

    def sweep_superseded(self, table: str, older_than: float = SUPERSEDED_GRACE) -> int:
        """Delete segments that a compaction older than ``older_than`` seconds replaced; call it
        holding the writer lock. Returns how many files went."""
        removed = 0
        for record, names, at in self.superseded(table):
            if time.time() - at < older_than:
                continue
            for name in names:
                try:
                    (self.table_dir(table) / name).unlink()
                    removed += 1
                except FileNotFoundError:
                    pass
            record.unlink(missing_ok=True)
        return removed

    def read_segment(self, path: Path, columns: list[str] | None = None) -> pa.Table | None:
        """One segment (only the ``columns`` it has, when given), or None when it cannot be read.

        A segment is read whole, with its page checksums verified and its columns checked
        (:data:`REQUIRED_COLUMNS`; those it lists, else :data:`TABLE_COLUMNS`), the first time this
        store object sees it (by path, size and mtime); one that fails, or a folder in its place, is
        reported once (and quarantined by the lock's holder), as is one :meth:`require_columns`
        found lacking. A segment that vanished meanwhile (compacted away by another process) is
        None, silently.
        """
        try:
            st = path.stat()
            if not stat.S_ISREG(st.st_mode):  # a fifo would block the read
                what = "a folder, not a file" if stat.S_ISDIR(st.st_mode) else "not a regular file"
                self._report_bad(path, what, move=self.quarantine_bad)
                return None
            ident = (str(path), st.st_size, st.st_mtime_ns)
            if ident in self._condemned:
                return None
            names = self._checked.get(ident)
            if names is None:
                whole = read_parquet(path, verify=True)
                listed = check_column_list(whole)
                mismatch = self._columns_mismatch(path, whole.schema, listed)
                if mismatch:
                    self._report_bad(path, mismatch, move=self.quarantine_bad)
                    return None
                self._checked[ident] = whole.column_names
                if not listed:
                    self._unlisted.add(ident)
                return whole.select([c for c in columns if c in whole.column_names]) if columns else whole
            return read_parquet(path, [c for c in columns if c in names] if columns else None)
        except FileNotFoundError:
            return None
        except PermissionError as exc:  # pyarrow's strerror holds the path and more: the errno's words
            self._report_bad(path, f"{os.strerror(exc.errno or errno.EACCES)}; fix its permissions", move=False,
                             repairable=False)
            return None
        except READ_ERRORS as exc:
            self._report_bad(path, _first_line(exc), move=self.quarantine_bad)
            return None

    def _columns_mismatch(self, path: Path, schema: pa.Schema, listed: bool = True) -> str:
        """Why the file at ``path`` cannot hold its table's rows ("" when it can): it lacks a
        column the table needs, or its key is not text (a file of another table, a query's export),
        or, listing no columns of its own (``listed``), it lacks one of :data:`TABLE_COLUMNS`."""
        folder = path.parent
        kind = folder.name if folder.parent == self.root / "tables" or folder == self.root / "jobs" else None
        for column in REQUIRED_COLUMNS.get(kind or "", ()):
            if column not in schema.names:
                return f"its columns are not the {kind} table's: it has no {column} column"
            if not pa.types.is_string(schema.field(column).type):
                return f"its columns are not the {kind} table's: its {column} is {schema.field(column).type}, not text"
        if kind == "jobs" or listed:
            return ""
        return lacking_columns(schema.names, TABLE_COLUMNS.get(kind or "", ()), f"every {kind} row has")

    def require_columns(self, table: str, columns: Iterable[str], keys: Collection[str], whose: str) -> list[Path]:
        """Segments of ``table`` that hold a row of one of ``keys`` but lack one of ``columns``:
        what every row of those keys has (a prediction, its evaluator's columns, which
        :data:`TABLE_COLUMNS` cannot know). Each is reported as damaged (``whose`` columns it
        lacks, for the warning), quarantined by the lock's holder, and read as unreadable by this
        store object from now on, so the rows of its keys are recomputed.

        Only segments that list no columns of their own are judged: one that lists them was
        written with those and is held to them (:func:`check_column_list`).
        """
        wanted = list(columns)
        found: list[Path] = []
        for path, ident in self._unlisted_segments(table):
            why = lacking_columns(self._checked[ident], wanted, whose)
            if why and self._holds_any(path, table, keys):
                self._condemned.add(ident)
                self._keys.pop(table, None)
                self._report_bad(path, why, move=self.quarantine_bad)
                found.append(path)
        return found

    def unlisted_segments(self, table: str) -> list[Path]:
        """The readable segments of ``table`` that list no columns of their own (see :meth:`require_columns`)."""
        return [path for path, _ in self._unlisted_segments(table)]

    def _unlisted_segments(self, table: str) -> list[tuple[Path, tuple[str, int, int]]]:
        """(segment, its identity) for each readable segment of ``table`` that lists no columns."""
        out = []
        for path in self.segments(table):
            try:
                st = path.stat()
            except OSError:
                continue
            ident = (str(path), st.st_size, st.st_mtime_ns)
            if ident not in self._checked:
                self.read_segment(path, [KEY_COLUMN[table]])  # checks it whole, once per store object
            if ident in self._unlisted and ident in self._checked and ident not in self._condemned:
                out.append((path, ident))
        return out

    def _holds_any(self, path: Path, table: str, keys: Collection[str]) -> bool:
        """Whether the segment at ``path`` holds a row of one of ``keys``."""
        data = self.read_segment(path, [KEY_COLUMN[table]])
        return data is not None and any(key in keys for key in data.column(0).to_pylist())

    def _read_all(self, table: str, columns: list[str] | None) -> list[tuple[Path, pa.Table]]:
        """(segment, rows) for every readable segment of ``table``; unreadable ones are quarantined.
        A segment compacted away between listing and reading makes it list again, so a reader
        racing a compaction sees the merged segment instead of a gap."""
        parts: list[tuple[Path, pa.Table]] = []
        for _ in range(5):
            parts, vanished = [], False
            for path in self.segments(table):
                data = self.read_segment(path, columns)
                if data is not None:
                    parts.append((path, data))
                elif not path.exists() and str(path) not in self._bad:
                    vanished = True
            if not vanished:
                break
        return parts

    def readable_segments(self, table: str) -> list[Path]:
        """Segments of ``table`` that read without error (unreadable ones are quarantined)."""
        return [path for path, _ in self._read_all(table, [KEY_COLUMN[table]])]

    def table(self, table: str, columns: list[str] | None = None) -> pa.Table | None:
        """Every readable row of ``table`` (duplicates included), or None if it has no segments."""
        parts = [data for _, data in self._read_all(table, columns)]
        if not parts:
            return None
        return pa.concat_tables(parts, promote_options="permissive")

    def keys(self, table: str) -> set[str]:
        """Every key with a complete row in ``table`` (a new set: the caller may change it)."""
        return set(self.key_set(table))

    def key_set(self, table: str) -> frozenset[str]:
        """Every key with a complete row in ``table``, read-only (:meth:`keys` without the copy).

        Remembered while the table's segments stay the same files, as a run asks several times
        (a million keys take a second to read).
        """
        column = KEY_COLUMN[table]
        state = self._segment_state(table)
        remembered = self._keys.get(table)
        if remembered is None or remembered[0] != state:
            data = self.table(table, [column])
            keys = frozenset(data.column(column).to_pylist()) if data is not None else frozenset()
            self._keys[table] = remembered = (state, keys)  # as listed before reading: a change since shows
        return remembered[1]

    def _segment_state(self, table: str) -> tuple[tuple[str, int, int, int], ...]:
        """Which files ``table``'s segments are now (path, size, mtime, inode): segments are only
        ever added, replaced or removed whole, so equal states hold equal rows."""
        out = []
        for path in self.segments(table):
            try:
                st = path.stat()
            except OSError:
                continue
            out.append((str(path), st.st_size, st.st_mtime_ns, st.st_ino))
        return tuple(out)

    def column_map(self, table: str, column: str) -> dict[str, Any]:
        """Key → ``column`` of its first row (the row the views show), for keys that have one."""
        key = KEY_COLUMN[table]
        data = self.table(table, [key, column])
        if data is None or column not in data.column_names:
            return {}
        out: dict[str, Any] = {}
        for k, v in zip(data.column(key).to_pylist(), data.column(column).to_pylist()):
            out.setdefault(k, v)
        return out

    def digests(self, table: str, column: str = DIGEST_COLUMN) -> dict[str, set[str]]:
        """Key → the blob digests its rows recorded in ``column`` (a ``truths`` row records one per
        pass: ``TRUTH_BLOBS``); rows written before digests existed add none."""
        key = KEY_COLUMN[table]
        data = self.table(table, [key, column])
        out: dict[str, set[str]] = {}
        if data is None:
            return out
        digests = data.column(column).to_pylist() if column in data.column_names else [None] * len(data)
        for k, d in zip(data.column(key).to_pylist(), digests):
            entry = out.setdefault(k, set())
            if d:
                entry.add(d)
        return out

    def view_files(self, experiment: str | None = None) -> dict[str, list[Path]]:
        """The files each view of :meth:`connect` reads: a table's readable segments, and under
        ``jobs`` the experiment's jobs file when it reads (tables without files are left out)."""
        files = {table: segments for table in TABLES if (segments := self.readable_segments(table))}
        jobs_path = self.jobs_path(experiment) if experiment is not None else None
        if jobs_path is not None and self.read_segment(jobs_path, ["pred_key"]) is not None:
            files["jobs"] = [jobs_path]
        return files

    def connect(self, experiment: str | None = None,
                files: dict[str, list[Path]] | None = None) -> duckdb.DuckDBPyConnection:
        """An in-memory DuckDB connection with views over this store's Parquet files.

        Views: one per table of :data:`TABLES` (deduplicated by key: a key's first row, or its
        newest in the tables of :data:`NEWEST_WINS`), and when ``experiment`` has a plan, ``jobs`` (its latest plan). Storage only: how
        they join into ``results``, and what counts, is the aggregate stage's
        (``sweep3d.results.results``), which adds its views on top
        (``sweep3d.results.connect``).
        Unreadable segments are left out (and quarantined). The views read the segments listed
        now; a compaction keeps the files it replaced for ``SUPERSEDED_GRACE`` seconds, so a
        connection stays good that long whatever happens to the store meanwhile.

        Args:
            files: the listing from :meth:`view_files`, when the caller needs to know exactly
                which files the views read (to :func:`lock_down` the connection to them).
        """
        files = self.view_files(experiment) if files is None else files
        con = duckdb.connect()
        for table in TABLES:
            if table in files:
                listing = ", ".join(_sql_str(str(p)) for p in files[table])
                con.execute(
                    f"CREATE VIEW {table} AS SELECT * FROM read_parquet([{listing}], union_by_name = true) "
                    f"QUALIFY row_number() OVER (PARTITION BY {KEY_COLUMN[table]} ORDER BY {row_order(table)}) = 1"
                )
        if "jobs" in files:
            con.execute(f"CREATE VIEW jobs AS SELECT * FROM read_parquet({_sql_str(str(files['jobs'][0]))})")
        return con

    # -- damage control ----------------------------------------------------------------------
    @property
    def unreadable(self) -> dict[str, str]:
        """Files this store object found unreadable (path → why), each reported once."""
        return dict(self._bad)

    def require_readable(self, spec: str | Path) -> None:
        """Refuse an answer that would leave out the rows of a file this store object found
        unreadable (a reader reads around it with a warning, which a query's or a summary's
        numbers would not show): one line naming the file, or the folder that denies it, and the fix.

        Args:
            spec: the spec's path, for the command that repairs a damaged file.

        Raises:
            StoreReadError: a file read so far could not be read.
        """
        if not self._bad:
            return
        path, why = next(iter(self._bad.items()))
        denied = why.endswith(f"; {FIXES[errno.EACCES]}")
        reason, fix = ((why.removesuffix(f"; {FIXES[errno.EACCES]}"), FIXES[errno.EACCES]) if denied else
                       (why, f"run: sweep3d cache verify {_spec_arg(spec)} --repair (it moves the file aside; the next run "
                             "computes its rows again)"))
        others = f" (and {len(self._bad) - 1} more)" if len(self._bad) > 1 else ""
        raise StoreReadError(f"cannot read {_blocked(Path(path)) if denied else path} ({reason}){others}: no answer "
                             f"is given, as one without its rows would be partial; {fix}")

    def _report_bad(self, path: Path, why: str, move: bool, repairable: bool = True) -> None:
        """Warn once that ``path`` is unreadable (``why``), moving it to ``quarantine/`` when ``move``
        and this object holds the lock. ``repairable``: ``cache verify --repair`` would move it aside
        (not a file the OS refused to read, which may be intact)."""
        if str(path) in self._bad:
            return
        why = re.sub(r"^(\w+: )Could not open Parquet input source '[^']*': ", r"\1", why.replace(str(path), path.name))
        self._bad[str(path)] = why
        where = _relative(path, self.root)
        moved = move and self.holds_lock and self.quarantine(path) is not None
        if not self.warn:
            return
        if moved:
            log.warning(f"warning: {where} is unreadable ({why}); moved it to quarantine/, its rows will be "
                        "recomputed")
        elif repairable:
            log.warning(f"warning: {where} is unreadable ({why}); skipping it (sweep3d cache verify --repair "
                        "moves it aside)")
        else:
            log.warning(f"warning: {where} is unreadable ({why}); skipping it")

    def quarantine(self, path: Path) -> Path | None:
        """Move a damaged file under ``quarantine/`` (same relative path); None if it could not be moved."""
        target = self.root / "quarantine" / _relative(path, self.root)
        if target.exists():
            target = target.with_name(f"{target.name}.{uuid.uuid4().hex[:8]}")
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(path, target)
        except OSError:
            return None
        return target

    def drop_rows(self, table: str, keys: set[str] | list[str]) -> int:
        """Remove every row of ``keys`` from ``table``, rewriting the segments that hold them.

        Each segment is replaced atomically, so a reader sees it with or without the rows, never
        half; call it holding the writer lock. Returns the number of rows removed.
        """
        keys = set(keys)
        if not keys:
            return 0
        column = KEY_COLUMN[table]
        value_set = pa.array(sorted(keys), type=pa.string())
        removed = 0
        for path in self.readable_segments(table):
            data = self.read_segment(path)
            if data is None:
                continue
            hit = pc.fill_null(pc.is_in(data.column(column), value_set=value_set), False)
            count = pc.sum(hit).as_py() or 0
            if not count:
                continue
            kept = data.filter(pc.invert(hit))
            if kept.num_rows:
                self.write_table_file(path, kept)
            else:
                path.unlink(missing_ok=True)
            removed += count
        return removed

    def discard(self, table: str, keys: set[str] | list[str], why: str) -> None:
        """Forget ``keys`` of a blob table whose blobs are missing or damaged, so they are recomputed:
        their rows are dropped and their blobs moved to ``quarantine/`` (one warning per call)."""
        keys = set(keys)
        if not keys:
            return
        self.drop_rows(table, keys)
        suffixes = TRUTH_BLOBS if table == "truths" else (BLOB_EXT,)  # a truth key owns its pass blobs
        for key in keys:
            for suffix in suffixes:
                blob = self.blob_path(key, suffix)
                if blob.exists():
                    self.quarantine(blob)
        sample = ", ".join(sorted(k[:12] for k in keys)[:3])
        log.warning(f"warning: {len(keys)} {table} blob(s) {why} ({sample}{', …' if len(keys) > 3 else ''}); "
                    "recomputing them")

    # -- locking -----------------------------------------------------------------------------
    @property
    def holds_lock(self) -> bool:
        """Whether this process holds the store's writer lock (through any store object)."""
        return os.path.realpath(self.root) in _HELD

    @contextmanager
    def lock(self, wait: float = 0.0) -> Iterator[None]:
        """Hold the store's writer lock; readers never take it.

        A command that writes takes it before it computes anything, and holds it to its end; what
        it runs within (``confirm``'s and ``realism score --engine``'s run) takes it again in the
        same thread, which holds it already: that is a no-op. Another thread of this process is
        refused as another process is.

        Raises:
            StoreBusyError: if another process or thread holds it for longer than ``wait`` seconds.
            StoreWriteError: the lock file cannot be opened (its permissions, a folder in its place).
        """
        held = os.path.realpath(self.root)
        if _HELD.get(held) == threading.get_ident():  # within the same thread's hold: already this caller's
            try:
                yield
            finally:
                self.forget_states()
            return
        self.ensure_writable()
        path = self.root / "lock"
        try:
            fh = open(path, "a+")
        except OSError as exc:
            raise store_error(exc, "write") from None
        deadline = time.monotonic() + wait
        try:
            while True:
                try:
                    fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if time.monotonic() >= deadline:
                        fh.seek(0)
                        holder = fh.read().strip() or "another process"
                        raise StoreBusyError(
                            f"store {self.root} is in use by {holder}; wait for it to finish or pass --wait SECONDS"
                        ) from None
                    time.sleep(0.2)
            fh.seek(0)
            fh.truncate()
            fh.write(f"sweep3d pid {os.getpid()}")
            fh.flush()
            _HELD[held] = threading.get_ident()
            try:
                yield
            finally:
                _HELD.pop(held, None)
                self.forget_states()  # taken under this lock: not to be trusted after it
        finally:
            fh.close()


class SegmentWriter:
    """Buffers rows and writes a segment every ``every`` seconds or ``max_rows`` rows, whichever
    comes first, so a kill loses one small batch at most."""

    def __init__(self, store: Store, table: str, schema: pa.Schema | None, every: float, max_rows: int) -> None:
        self.store, self.table, self.schema, self.every = store, table, schema, every
        self.max_rows = max_rows
        self.rows: list[dict[str, Any]] = []
        self.last = time.monotonic()
        self.written = 0

    def add(self, row: dict[str, Any]) -> None:
        self.rows.append(row)
        if len(self.rows) >= self.max_rows or time.monotonic() - self.last >= self.every:
            self.flush()

    def flush(self) -> None:
        if self.rows:
            self.store.append(self.table, self.rows, self.schema)
            self.written += len(self.rows)
            self.rows = []
        self.last = time.monotonic()

    def __enter__(self) -> "SegmentWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.flush()


# -- a segment's columns ------------------------------------------------------------------------
def row_order(table: str) -> str:
    """SQL ordering a key's rows of ``table`` so that the one that counts comes first (:data:`NEWEST_WINS`)."""
    return "created_at DESC" if table in NEWEST_WINS else "created_at"


def photo_path(root: Path, sha256: str) -> Path:
    """The kept copy of the photograph whose file has the SHA-256 ``sha256`` (:data:`PHOTOS_FOLDER`)."""
    return root.joinpath(*PHOTOS_FOLDER, f"{sha256}.jpg")


def with_column_list(table: pa.Table) -> pa.Table:
    """``table`` with the list of its columns in its metadata, so a segment that later lacks one
    (a tool rewrote it without a column) reads as damaged rather than as rows with nulls."""
    metadata = {**(table.schema.metadata or {}), COLUMNS_METADATA: json.dumps(table.column_names).encode()}
    return table.replace_schema_metadata(metadata)


def check_column_list(table: pa.Table) -> bool:
    """Raise ValueError (a read error: the segment is damaged) when ``table`` lacks a column its
    metadata lists. Returns whether it lists its columns: one that does not (written before the
    list was kept, or stripped of it) is judged by its table's columns instead (:data:`TABLE_COLUMNS`)."""
    listed = (table.schema.metadata or {}).get(COLUMNS_METADATA)
    if listed is None:
        return False
    try:
        missing = [c for c in json.loads(listed) if c not in table.column_names]
    except (ValueError, TypeError):
        raise ValueError("its list of columns is not readable") from None
    if missing:
        raise ValueError(f"it lacks its column{'s' * (len(missing) > 1)} {', '.join(map(repr, missing))}")
    return True


def lacking_columns(names: Iterable[str], required: Iterable[str], whose: str) -> str:
    """Why a segment with columns ``names`` is damaged ("" when it is not): it lacks one of the
    ``required`` columns, which ``whose`` rows have (and lists no columns of its own to say so)."""
    have = set(names)
    missing = [c for c in required if c not in have]
    if not missing:
        return ""
    return (f"it lacks the column{'s' * (len(missing) > 1)} {', '.join(map(repr, missing))} that {whose}, and lists "
            "no columns of its own: rewritten without them")


def lock_down(con: duckdb.DuckDBPyConnection, readable: Iterable[Path], writable: Iterable[Path] = ()) -> None:
    """Let ``con`` open only the files ``readable`` and ``writable`` from now on, and change no setting.

    For SQL from users (``sweep3d query``): a statement then cannot read other files, attach a
    database file, install or load an extension, spill to a temp folder or undo this. DuckDB's
    allow-list does not tell reading from writing, so a ``COPY`` or ``ATTACH`` could still write
    the listed files themselves: run only user statements that :func:`is_select` accepts.
    """
    allowed = sorted({variant for p in [*readable, *writable] for variant in (os.path.abspath(p), os.path.realpath(p))})
    con.execute("SET temp_directory = ''")  # its folder would be allowed, writes included
    con.execute(f"SET allowed_paths = [{', '.join(_sql_str(p) for p in allowed)}]")
    con.execute("SET enable_external_access = false")
    con.execute("SET lock_configuration = true")


def is_select(statement: str) -> bool:
    """Whether ``statement`` is exactly one read-only query (SELECT, WITH, FROM, VALUES, SHOW, …),
    as DuckDB's own parser reads it; a parse error raises ``duckdb.Error``."""
    parsed = duckdb.extract_statements(statement)
    return len(parsed) == 1 and parsed[0].type == duckdb.StatementType.SELECT


def safe_filename(name: str) -> str:
    """A file name for ``name`` that no other name maps to.

    A short name of letters, digits and ``-_.`` is its own file name (existing stores keep their
    paths). Any other keeps those characters, replaces the rest with ``_`` and adds ``~`` and a
    hash of the exact name: ``a/b`` and ``a_b`` once shared a jobs file, and ``~`` never appears
    in a name that is its own file name.
    """
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)
    if safe == name and len(name.encode()) <= MAX_FILENAME_BYTES:
        return name
    short = safe.encode()[:MAX_FILENAME_BYTES].decode(errors="ignore")
    return f"{short}~{hashlib.sha256(name.encode()).hexdigest()[:16]}"


def utc_now() -> datetime:
    """Now, in UTC, as a naive timestamp (tz-aware ones would need pytz to read back through DuckDB)."""
    return datetime.now(timezone.utc).replace(tzinfo=None)


#: The way out of a full or read-only disk under the store (a file the user chose elsewhere has its own).
STORE_FIX = "set experiment.store to a folder on another disk"


def atomic_write(path: Path, data: bytes, durable: bool = True, fix: str = STORE_FIX) -> None:
    """Write ``data`` to ``path`` through a temp file in the same folder and a rename; the folder
    is made when it is missing (not asked for each time: writers of many small files call this).

    Args:
        durable: fsync before the rename; a cache whose damaged file is only a miss may skip it.
        fix: what the error advises besides freeing space or permissions: the store's own way
            (:data:`STORE_FIX`), or, for a file written outside the store, how to write it elsewhere.

    Raises:
        StoreWriteError: the disk is full or the folder is not writable (no temp file is left).
    """
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        try:
            fh = open(tmp, "wb")
        except FileNotFoundError:  # its folder is not there yet
            path.parent.mkdir(parents=True, exist_ok=True)
            fh = open(tmp, "wb")
        with fh:
            fh.write(data)
            if durable:
                fh.flush()
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        _unlink_quietly(tmp)
        if _is_write_error(exc):
            raise _as_write_error(exc, path, fix) from None
        raise


def _is_write_error(exc: BaseException) -> bool:
    if not isinstance(exc, OSError):
        return False
    return exc.errno in WRITE_ERRNOS or "No space left on device" in str(exc)


def _as_write_error(exc: BaseException, path: Path, fix: str = STORE_FIX) -> StoreWriteError:
    assert isinstance(exc, OSError)
    code = exc.errno if exc.errno in WRITE_ERRNOS else errno.ENOSPC
    reason = exc.strerror or os.strerror(code)
    if code in (errno.EISDIR, errno.ENOTDIR):
        return StoreWriteError(f"cannot write {path}: {reason}; {FIXES[code]}")
    if code in FULL_ERRNOS:
        return full_disk_error(OSError(code, reason), f"write {path}", path, fix)
    return StoreWriteError(f"cannot write {path}: {reason}; make the folder writable, or {fix}")


#: What a full disk, or a used-up quota, raises.
FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)


def is_full_disk(exc: BaseException) -> bool:
    """Whether ``exc`` says the disk (or the user's quota) is full, however it lost its path."""
    return isinstance(exc, OSError) and (exc.errno in FULL_ERRNOS or "No space left on device" in str(exc))


def full_disk_error(exc: OSError, doing: str, path: Path, fix: str = STORE_FIX) -> StoreWriteError:
    """One line for a full disk met while ``doing`` (``"write <path>"``) at ``path``: that the disk
    is full, which one (where it is mounted, what is left) and the fix (``fix``: the store's, or
    how to write a file of the user's choosing elsewhere)."""
    reason = exc.strerror or os.strerror(exc.errno or errno.ENOSPC)
    what = "the disk quota is used up" if exc.errno == errno.EDQUOT else "the disk is full"
    mount = mount_point(path)
    try:
        left = f"{_size(shutil.disk_usage(mount).free)} free on the disk mounted at {mount}"
    except OSError:
        left = f"the disk mounted at {mount}"
    return StoreWriteError(f"cannot {doing}: {what} ({reason}; {left}); free some disk space, or {fix}")


def mount_point(path: Path) -> Path:
    """The mount point of the file system ``path`` (or its nearest existing folder) is on."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    while not os.path.ismount(path) and path != path.parent:
        path = path.parent
    return path


def _size(n: int) -> str:
    """``n`` bytes for a person: ``0 B``, ``512 kB``, ``3.2 GB``."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n} B"


def store_error(exc: OSError, doing: str) -> StoreReadError | StoreWriteError:
    """One line for ``exc``, met reading or writing (``doing``) a path of the store: the path
    (for a permission, the outermost folder that denies it) and how to fix it."""
    path = Path(exc.filename) if exc.filename else Path(".")
    if exc.errno in (errno.EACCES, errno.EPERM):
        path = _blocked(path)
    error = StoreReadError if doing == "read" else StoreWriteError
    return error(f"cannot {doing} {path} ({exc.strerror or exc}); {FIXES.get(exc.errno or 0, 'check the disk')}")


def _blocked(path: Path) -> Path:
    """The outermost of ``path`` and its folders that this process may not read (``path`` itself
    when none is found: a denial that ``os.access`` does not see)."""
    for folder in reversed(path.parents):
        if not os.access(folder, os.R_OK | os.X_OK):
            return folder
    return path


def scan(folder: Path) -> list[os.DirEntry]:
    """The entries of ``folder`` ([] when it is not there).

    Raises:
        StoreReadError: it cannot be read (its permissions, a file in its place): never taken
            for an empty folder, or gc would delete every blob whose row it could not see.
    """
    try:
        with os.scandir(folder) as entries:
            return list(entries)
    except FileNotFoundError:
        return []
    except OSError as exc:
        raise store_error(exc, "read") from None


def blob_key(name: str, folder: str) -> str | None:
    """The key whose blob the file ``name`` in the blob folder ``folder`` is; None when the store
    gives no blob that name (``<key>.png``, ``<key>.mask.png``, ``<key>.depth.npz``: the key hex
    and beginning with the folder's name, as :meth:`Store.blob_file` places it)."""
    for suffix in BLOB_SUFFIXES:
        key = name[:-len(suffix)]
        if name.endswith(suffix) and key[:2] == folder and _HEX.fullmatch(key):
            return key
    return None


def read_parquet(path: str | Path, columns: list[str] | None = None, verify: bool = False) -> pa.Table:
    """One Parquet file as a table, its schema's metadata kept (``verify``: check page checksums).

    Through ``pq.ParquetFile``, not ``pq.read_table``: the latter goes through pyarrow.dataset,
    whose import (pandas' with it) adds 0.3 s to every command that reads the store."""
    with pq.ParquetFile(path, page_checksum_verification=verify) as parquet:
        return parquet.read(columns=columns)


def _folder_entries(folder: Path) -> int:
    """About how many entries ``folder`` holds, from its size (no listing); 0 when it is not there."""
    try:
        return os.stat(folder).st_size // 32  # ext4: 8 bytes + a 44-character name per entry; tmpfs: 20
    except OSError:
        return 0


def _holds(path: Path, data: pa.Buffer) -> bool:
    """Whether the file at ``path`` holds exactly ``data``."""
    try:
        if os.stat(path).st_size != data.size:
            return False
        with open(path, "rb") as fh:
            return pa.py_buffer(fh.read()).equals(data)
    except OSError:
        return False


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


def _unlink_quietly(path: Path) -> None:
    try:
        path.unlink()
    except OSError:
        pass


def segment_name() -> str:
    """A new segment's file name: sorts in write order, unique across processes."""
    return f"{time.time_ns():020d}-{os.getpid()}-{uuid.uuid4().hex[:8]}.parquet"


def _is_segment_name(name: str) -> bool:
    """Whether ``name`` could be a segment's (a ``.parquet`` file's name, no folder, not hidden):
    a compaction record naming anything else is not followed out of the table's folder."""
    return name.endswith(".parquet") and not name.startswith(".") and name == Path(name).name


def _spec_arg(spec: str | Path) -> str:
    """``spec`` as a command names it: SPEC for one loaded from no file (``<dict>``, ``<string>``)."""
    return "SPEC" if str(spec).startswith("<") else str(spec)


def _relative(path: Path, root: Path) -> Path:
    try:
        return path.relative_to(root)
    except ValueError:
        return Path(path.name)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}"


def _sql_str(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"
