"""Store upkeep behind ``sweep3d cache``: verify (and repair), garbage-collect, compact, stats.

Blobs are named by cache key, not by content, so a blob's integrity is checked against the
SHA-256 its row recorded when it was written (rows from before digests existed fall back to
"the PNG decodes"). A segment is corrupt when it fails to read with its page checksums verified.
Repairs and compaction change the store only through atomic renames, holding the writer lock,
so a reader sees every row exactly once before, during and after them.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import pyarrow as pa
import pyarrow.compute as pc

from sweep3d.cache.blobs import blob_is_intact
from sweep3d.cache.store import (
    BLOB_TABLES,
    KEY_COLUMN,
    TABLES,
    TRUTH_BLOBS,
    Store,
    atomic_write,
    segment_name,
)

TEMP_AGE = 3600.0  # seconds after which gc removes temp files (a live run's are younger)
#: Folders that only the writer lock's holder writes (``reports/`` and ``cache/`` are not:
#: ``sweep3d report`` writes them without the lock).
LOCKED_FOLDERS = ("tables", "blobs", "jobs", "models", "outputs")
TEMP_PATTERN = ".*.tmp"  # how atomic_write names its temp files (a dot, the file's name, a tag, .tmp)


# -- verify ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Problem:
    kind: str  # "corrupt segment", "corrupt blob", "missing blob", "corrupt jobs table"
    table: str
    path: Path
    key: str | None = None
    detail: str = ""

    def line(self, root: Path) -> str:
        where = self.path.relative_to(root) if self.path.is_relative_to(root) else self.path
        return f"{self.kind}: {where}" + (f" ({self.detail})" if self.detail else "")


@dataclass
class Verification:
    segments: int = 0
    rows: int = 0
    blobs: int = 0
    problems: list[Problem] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems


def verify(root: Path) -> Verification:
    """Re-read every segment and re-hash every blob that a row references; change nothing."""
    store = Store(root, quarantine=False, warn=False)
    report = Verification()
    for table in TABLES:
        for path in store.segments(table):
            report.segments += 1
            data = store.read_segment(path)
            if data is None:
                if path.exists():
                    report.problems.append(Problem("corrupt segment", table, path, detail=store.unreadable.get(str(path), "")))
                continue
            report.rows += data.num_rows
    for path in sorted((root / "jobs").glob("*.parquet")):
        if store.read_segment(path) is None and path.exists():
            report.problems.append(Problem("corrupt jobs table", "jobs", path, detail=store.unreadable.get(str(path), "")))
    for table in BLOB_TABLES:
        for key, digests in sorted(store.digests(table).items()):
            path = store.blob_path(key)
            report.blobs += 1
            try:
                data = path.read_bytes()
            except FileNotFoundError:
                report.problems.append(Problem("missing blob", table, path, key))
                continue
            except OSError as exc:
                report.problems.append(Problem("corrupt blob", table, path, key, exc.strerror or str(exc)))
                continue
            if not blob_is_intact(data, digests):
                detail = "content does not match its recorded SHA-256" if digests else "does not decode"
                report.problems.append(Problem("corrupt blob", table, path, key, detail))
    _verify_truth_blobs(store, report)
    return report


def _verify_truth_blobs(store: Store, report: Verification) -> None:
    """Re-hash the mask and depth blobs the ``truths`` rows record (truth passes, when used)."""
    data = store.table("truths")
    if data is None:
        return
    rows = data.to_pylist()
    for suffix, column in TRUTH_BLOBS.items():
        digests: dict[str, set[str]] = {}
        for row in rows:
            if row.get(column):
                digests.setdefault(row["truth_key"], set()).add(row[column])
        for key, wanted in sorted(digests.items()):
            path = store.blob_path(key, suffix)
            report.blobs += 1
            try:
                ok = hashlib.sha256(path.read_bytes()).hexdigest() in wanted
            except FileNotFoundError:
                report.problems.append(Problem("missing blob", "truths", path, key))
                continue
            except OSError as exc:
                report.problems.append(Problem("corrupt blob", "truths", path, key, exc.strerror or str(exc)))
                continue
            if not ok:
                report.problems.append(Problem("corrupt blob", "truths", path, key,
                                               "content does not match its recorded SHA-256"))


def repair(root: Path, report: Verification) -> int:
    """Fix what :func:`verify` found; call it holding the writer lock. Returns problems fixed.

    Corrupt segments and jobs tables go to ``quarantine/`` (their rows are recomputed by the
    next run); rows whose blob is missing or corrupt are dropped and the blob quarantined, so
    the next run renders or postprocesses them again.
    """
    store = Store(root)
    fixed = 0
    for problem in report.problems:
        if problem.kind in ("corrupt segment", "corrupt jobs table"):
            if store.quarantine(problem.path) is not None:
                fixed += 1
    for table in BLOB_TABLES:
        keys = {p.key for p in report.problems if p.table == table and p.key is not None}
        if keys:
            store.drop_rows(table, keys)
            for key in keys:
                blob = store.blob_path(key)
                if blob.exists():
                    store.quarantine(blob)
            fixed += len(keys)
    truths = {p.key for p in report.problems if p.table == "truths" and p.key is not None}
    if truths:  # the next run that needs them renders the passes again
        store.drop_rows("truths", truths)
        for key in truths:
            for suffix in TRUTH_BLOBS:
                blob = store.blob_path(key, suffix)
                if blob.exists():
                    store.quarantine(blob)
        fixed += len(truths)
    return fixed


# -- gc ----------------------------------------------------------------------------------------
@dataclass
class Collected:
    blobs: int = 0
    temp_files: int = 0
    quarantined: int = 0
    bytes: int = 0


def collect_garbage(root: Path, older_than: float = TEMP_AGE, purge_quarantine: bool = False) -> Collected:
    """Remove blobs that no row references, and temp files and segments a compaction replaced
    that are older than ``older_than`` seconds.

    Call it holding the writer lock (no run is writing). ``purge_quarantine`` also empties
    ``quarantine/``.
    """
    store = Store(root)
    referenced: set[str] = set()
    for table in (*BLOB_TABLES, "truths"):  # a truth key owns its mask and depth blobs
        referenced |= store.keys(table)
    out = Collected()
    now = time.time()

    def remove(path: Path) -> bool:
        try:
            size = path.stat().st_size
            path.unlink()
        except OSError:
            return False
        out.bytes += size
        return True

    blobs = root / "blobs"
    for path in sorted(blobs.glob("*/*")) if blobs.is_dir() else []:
        if not path.is_file():
            continue
        if path.name.startswith("."):
            if now - path.stat().st_mtime >= older_than and remove(path):
                out.temp_files += 1
        elif path.name.split(".", 1)[0] not in referenced and remove(path):
            out.blobs += 1
    for table in TABLES:
        out.temp_files += store.sweep_superseded(table, older_than)
    for folder in (root / "tables", root / "jobs", root / "reports"):
        for path in folder.rglob(".*.tmp") if folder.is_dir() else []:
            if now - path.stat().st_mtime >= older_than and remove(path):
                out.temp_files += 1
    scratch = root / "tmp"
    for path in sorted(scratch.rglob("*"), reverse=True) if scratch.is_dir() else []:
        if path.is_file() and now - path.stat().st_mtime >= older_than and remove(path):
            out.temp_files += 1
    quarantine = root / "quarantine"
    if purge_quarantine and quarantine.is_dir():
        for path in quarantine.rglob("*"):
            if path.is_file() and remove(path):
                out.quarantined += 1
    for folder in (blobs, scratch, quarantine):
        _remove_empty_dirs(folder)
    return out


def remove_killed_writers_temp_files(root: Path, store: Store | None = None) -> int:
    """Remove every temp file in the folders only the lock's holder writes; returns how many.

    Call it holding the writer lock, before writing: any temp file there then is a killed
    writer's (a live one would hold the lock), so unlike gc it need not wait for it to age.

    Args:
        store: the caller's store object: the blob folders are read through its listings
            (:meth:`Store.blob_listing`), which it then remembers for its own existence checks,
            so a run lists its million blobs once.
    """
    store = store if store is not None else Store(root)
    removed = 0
    for name in LOCKED_FOLDERS:
        folder = root / name
        if not folder.is_dir():
            continue
        for path in _blob_temp_files(store) if name == "blobs" else folder.rglob(TEMP_PATTERN):
            try:
                path.unlink()
            except OSError:
                continue
            removed += 1
    return removed


def _is_temp(name: str) -> bool:
    """Whether ``name`` matches :data:`TEMP_PATTERN`."""
    return len(name) >= 5 and name.startswith(".") and name.endswith(".tmp")


def _blob_temp_files(store: Store) -> Iterator[Path]:
    """What ``blobs/`` holds that matches :data:`TEMP_PATTERN`, at any depth (as ``rglob`` finds
    it), read from the store's listings of the blob folders: what a blob folder holds besides
    blobs (few names, if any) is looked at closer, and searched if it is a folder."""
    blobs = store.root / "blobs"
    with os.scandir(blobs) as listing:
        entries = list(listing)
    for entry in entries:
        if _is_temp(entry.name):
            yield Path(entry.path)
        if not entry.is_dir() or entry.is_symlink():
            continue
        for name in store.blob_listing(entry.name).others:
            path = blobs / entry.name / name
            if _is_temp(name):
                yield path
            if path.is_dir() and not path.is_symlink():
                yield from path.rglob(TEMP_PATTERN)


def _remove_empty_dirs(folder: Path) -> None:
    if not folder.is_dir():
        return
    for path in [*sorted((p for p in folder.rglob("*") if p.is_dir()), key=lambda p: len(p.parts), reverse=True),
                 folder]:
        try:
            path.rmdir()
        except OSError:
            pass


# -- compact -----------------------------------------------------------------------------------
@dataclass
class Compacted:
    table: str
    segments_before: int
    rows_before: int
    rows_after: int


def compact_table(store: Store, table: str) -> Compacted | None:
    """Merge every readable segment of ``table`` into one, dropping duplicate rows of a key
    (keeping the row the views show: the earliest ``created_at``). Call it holding the lock.

    The merged segment is written (atomically) first, then a record of the segments it replaces
    (from then on they are no longer listed); the replaced files stay on disk for
    ``SUPERSEDED_GRACE`` seconds so a reader that listed them just before can still read them.
    A reader sees the old segments, or old and merged ones (deduplicated by the views), or the
    merged one: never a gap. Returns None when there is nothing to merge.
    """
    store.sweep_superseded(table)
    paths = store.readable_segments(table)
    parts = [(p, store.read_segment(p)) for p in paths]
    parts = [(p, t) for p, t in parts if t is not None]
    if not parts:
        return None
    merged = pa.concat_tables([t for _, t in parts], promote_options="permissive")
    rows_before = merged.num_rows
    key = KEY_COLUMN[table]
    if "created_at" in merged.column_names:
        merged = merged.take(pc.sort_indices(merged, sort_keys=[("created_at", "ascending")]))
    seen: set[str] = set()
    first = [i for i, k in enumerate(merged.column(key).to_pylist()) if not (k in seen or seen.add(k))]
    if len(parts) == 1 and len(first) == rows_before:
        return None
    merged = merged.take(pa.array(first, type=pa.int64()))
    name = segment_name()
    store.write_table_file(store.table_dir(table) / name, merged)
    record = {"merged": name, "replaces": [p.name for p, _ in parts], "at": time.time()}
    atomic_write(store.table_dir(table) / f".compacted-{Path(name).stem}.json", json.dumps(record).encode())
    return Compacted(table, len(parts), rows_before, merged.num_rows)


# -- stats -------------------------------------------------------------------------------------
@dataclass
class TableStats:
    name: str
    files: int
    rows: int
    keys: int
    bytes: int


def store_stats(root: Path) -> list[TableStats]:
    """Files, rows, distinct keys and bytes per table, then blobs, temp files and quarantine."""
    store = Store(root, quarantine=False, warn=False)
    out = []
    for table in TABLES:
        paths = store.segments(table)
        data = store.table(table, [KEY_COLUMN[table]])
        rows = data.num_rows if data is not None else 0
        keys = len(set(data.column(0).to_pylist())) if data is not None else 0
        out.append(TableStats(table, len(paths), rows, keys, sum(_size(p) for p in paths)))
    jobs = sorted((root / "jobs").glob("*.parquet")) if (root / "jobs").is_dir() else []
    out.append(TableStats("jobs", len(jobs), sum(_rows(store, p) for p in jobs), len(jobs), sum(_size(p) for p in jobs)))
    blobs = [p for p in (root / "blobs").glob("*/*") if p.is_file() and not p.name.startswith(".")] \
        if (root / "blobs").is_dir() else []
    out.append(TableStats("blobs", len(blobs), len(blobs), len(blobs), sum(_size(p) for p in blobs)))
    replaced = [store.table_dir(t) / n for t in TABLES for _, names, _ in store.superseded(t) for n in names]
    replaced = [p for p in replaced if p.is_file()]
    out.append(TableStats("compacted away", len(replaced), 0, 0, sum(_size(p) for p in replaced)))
    temp = [p for p in root.rglob(".*.tmp")] if root.is_dir() else []
    out.append(TableStats("temp files", len(temp), 0, 0, sum(_size(p) for p in temp)))
    quarantine = [p for p in (root / "quarantine").rglob("*") if p.is_file()] if (root / "quarantine").is_dir() else []
    out.append(TableStats("quarantine", len(quarantine), 0, 0, sum(_size(p) for p in quarantine)))
    return out


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


def _rows(store: Store, path: Path) -> int:
    data = store.read_segment(path, ["job"])
    return data.num_rows if data is not None else 0
