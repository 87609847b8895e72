"""Store upkeep behind ``sweep3d cache``: verify (and repair), garbage-collect, compact, stats.

Blobs are named by cache key, not by content, so a blob's integrity is checked against the
SHA-256 its row recorded when it was written (rows from before digests existed fall back to
"the PNG decodes"); so are a model's kept outputs (``outputs/``, their digest in the file) and the
meshes extracted from archives (``assets/``, their digests in the folder's manifest). A segment is
corrupt when it fails to read with its page checksums verified, or lacks a column its rows always
have (its table's, or for predictions their evaluator's, as the plans in ``jobs/`` record it).
Repairs and compaction change the store only through atomic renames, holding the writer lock,
so a reader sees every row exactly once before, during and after them.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import pyarrow as pa
import pyarrow.compute as pc

from sweep3d.cache import digested, extracted
from sweep3d.cache.blobs import blob_is_intact
from sweep3d.cache.columns import with_column_list
from sweep3d.cache.contracts import KeptFiles, TableContract, contract_of, table_contracts, table_names
from sweep3d.cache.files import StoreReadError, atomic_write, scan, segment_name
from sweep3d.cache.store import Store
from sweep3d.cache.store_blobs import BLOB_TABLES, TRUTH_BLOBS, blob_key
from sweep3d.core import read_record

TEMP_AGE = 3600.0  # seconds after which gc removes temp files (a live run's are younger)
#: Folders that only the writer lock's holder writes (``reports/`` and ``cache/`` are not:
#: ``sweep3d report`` writes them without the lock), besides the folders of the declared tables'
#: kept files (see :func:`locked_folders`).
LOCKED_FOLDERS = ("tables", "blobs", "jobs", "models", "outputs")
_HEX_NAME = re.compile(r"[0-9a-f]{64}")  # a kept file's name, less its suffix: the SHA-256 its row records
TEMP_PATTERN = ".*.tmp"  # how atomic_write names its temp files (a dot, the file's name, a tag, .tmp)


# -- verify ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Problem:
    kind: str  # "corrupt segment", "corrupt blob", "missing blob", "corrupt jobs table", "corrupt kept output",
    # "corrupt extracted asset", and for a table's kept files "corrupt kept <noun>", "missing kept <noun>";
    # "unreadable …" for a file of any of these kinds that the OS would not let this process read (see
    # :data:`UNREADABLE`)
    table: str
    path: Path
    key: str | None = None
    detail: str = ""

    def line(self, root: Path) -> str:
        where = self.path.relative_to(root) if self.path.is_relative_to(root) else self.path
        return f"{self.kind}: {where}" + (f" ({self.detail})" if self.detail else "")

    @property
    def repairable(self) -> bool:
        """Whether ``--repair`` fixes it: a file whose bytes are wrong or missing. One the OS would not
        let sweep3d read may be intact: moving it aside would throw good results away."""
        return not self.kind.startswith(UNREADABLE)


#: How a problem's kind begins when the file could not be read at all (permissions, an I/O error).
UNREADABLE = "unreadable"


@dataclass
class Verification:
    segments: int = 0
    rows: int = 0
    blobs: int = 0
    outputs: int = 0  # kept model outputs
    assets: int = 0  # folders extracted from mesh archives
    kept: dict[KeptFiles, int] = field(default_factory=dict)  # a table's kept files -> how many were checked
    problems: list[Problem] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    @property
    def repairable(self) -> list[Problem]:
        """The problems ``--repair`` fixes (see :attr:`Problem.repairable`)."""
        return [p for p in self.problems if p.repairable]


def verify(root: Path) -> Verification:
    """Re-read every segment (checking its columns are its table's), re-hash every blob that a
    row references, every kept model output and every extracted mesh, check every kept file a
    declared table's rows name (its contract's check); change nothing."""
    store = Store(root, quarantine=False, warn=False)
    report = Verification()
    for table in table_names():
        for path in store.segments(table):
            report.segments += 1
            data = store.read_segment(path)
            if data is None:
                if path.exists():
                    report.problems.append(_file_problem("segment", table, path, store))
                continue
            report.rows += data.num_rows
    for path in evaluated_columns_lacking(store):
        report.problems.append(Problem("corrupt segment", "predictions", path, detail=store.unreadable.get(str(path), "")))
    for path in jobs_files(root):
        if store.read_segment(path) is None and path.exists():
            report.problems.append(_file_problem("jobs table", "jobs", path, store))
    for table in BLOB_TABLES:
        for key, digests in sorted(store.digests(table).items()):
            path = store.blob_path(key)
            report.blobs += 1
            try:
                data = path.read_bytes()
            except FileNotFoundError:
                if table == "images" and not digests:
                    continue  # not stored: made in memory ([postprocess] store = "none"), made again when looked at
                report.problems.append(Problem("missing blob", table, path, key))
                continue
            except OSError as exc:
                report.problems.append(_read_failed("blob", table, path, key, exc))
                continue
            if not blob_is_intact(data, digests):
                detail = "content does not match its recorded SHA-256" if digests else "does not decode"
                report.problems.append(Problem("corrupt blob", table, path, key, detail))
    _verify_truth_blobs(store, report)
    for contract in table_contracts():
        if contract.kept is not None:
            _verify_kept_files(store, contract, contract.kept, report)
    _verify_kept_outputs(root, report)
    _verify_assets(root, report)
    return report


def evaluated_columns_lacking(store: Store) -> list[Path]:
    """Predictions segments lacking a column of their rows' evaluator, as each experiment's plan
    (its jobs file) records it; found damaged in ``store`` (see :meth:`Store.require_columns`).
    Only segments that list no columns of their own are judged, so a store without such a
    segment reads no jobs file here."""
    if not store.unlisted_segments("predictions"):
        return []
    found: list[Path] = []
    for path in jobs_files(store.root):
        record = read_record(path)
        jobs = store.read_segment(path, ["pred_key"]) if record is not None else None
        if record is None or jobs is None:
            continue
        keys = set(jobs.column(0).to_pylist())
        columns = (*contract_of("predictions").columns, *record.columns)
        found += store.require_columns("predictions", columns, keys, f"every row of the {record.kind} evaluator has")
    return found


def kept_names(store: Store, contract: TableContract) -> set[str]:
    """The kept files ``contract``'s rows name (the values of its kept files' column): those in use."""
    kept = contract.kept
    if kept is None:
        return set()
    data = store.table(contract.name, [kept.column])
    if data is None or kept.column not in data.column_names:
        return set()
    return {d for d in data.column(kept.column).to_pylist() if d}


def _verify_kept_files(store: Store, contract: TableContract, kept: KeptFiles, report: Verification) -> None:
    """Check that every kept file ``contract``'s rows name is there and whole, by its contract's
    check (their bytes may be re-encoded, so no digest of them need be recorded)."""
    report.kept.setdefault(kept, 0)
    for name in sorted(kept_names(store, contract)):
        path = kept.path(store.root, name)
        report.kept[kept] += 1
        denied = cannot_open(path)
        if denied:
            report.problems.append(Problem(f"{UNREADABLE} kept {kept.noun}", contract.name, path, name, denied))
            continue
        try:
            why = kept.check(path)
        except FileNotFoundError:
            report.problems.append(Problem(f"missing kept {kept.noun}", contract.name, path, name, kept.missing_fix))
            continue
        except OSError as exc:
            report.problems.append(_read_failed(f"kept {kept.noun}", contract.name, path, name, exc))
            continue
        if why:
            report.problems.append(Problem(f"corrupt kept {kept.noun}", contract.name, path, name, why))


def _denied(exc: OSError) -> bool:
    """Whether the OS refused to read a file (its permissions, the disk: ``errno`` says which), not
    its bytes or its place (a folder where a file belongs is the store's damage, and is moved aside)."""
    return exc.errno is not None and exc.errno not in (errno.ENOENT, errno.EISDIR, errno.ENOTDIR)


def _why(exc: OSError) -> str:
    """What the OS said, and what to do about it."""
    fix = "fix its permissions" if isinstance(exc, PermissionError) else "check the disk"
    return f"{exc.strerror or type(exc).__name__}; {fix}"


def cannot_open(path: Path) -> str:
    """Why the OS will not let this process read ``path`` ("" when it will, or the file is gone or a
    folder: damage of another kind). Opened without blocking, so a FIFO in a file's place cannot hang."""
    try:
        os.close(os.open(path, os.O_RDONLY | os.O_NONBLOCK))
    except OSError as exc:
        return _why(exc) if _denied(exc) else ""
    return ""


def _read_failed(what: str, table: str, path: Path, key: str | None, exc: OSError) -> Problem:
    """The problem of a file of ``what`` kind whose read raised ``exc``: unreadable (left as it is) when
    the OS refused it, else corrupt (a folder in its place)."""
    if _denied(exc):
        return Problem(f"{UNREADABLE} {what}", table, path, key, _why(exc))
    return Problem(f"corrupt {what}", table, path, key, exc.strerror or str(exc))


def _file_problem(what: str, table: str, path: Path, store: Store) -> Problem:
    """The problem of a segment or jobs table that ``store`` could not read: unreadable when the OS
    refuses to open it, else corrupt (its bytes, its columns, a folder in its place)."""
    denied = cannot_open(path)
    if denied:
        return Problem(f"{UNREADABLE} {what}", table, path, detail=denied)
    return Problem(f"corrupt {what}", table, path, detail=store.unreadable.get(str(path), ""))


def _verify_kept_outputs(root: Path, report: Verification) -> None:
    """Check every kept model output (``outputs/``) against the digest it was written with."""
    for entry in store_files(root / digested.OUTPUTS_FOLDER):
        if not entry.name.endswith(digested.SUFFIX) or entry.name.startswith("."):
            continue
        report.outputs += 1
        path = Path(entry.path)
        why = digested.check_file(path)
        if why:
            denied = cannot_open(path)
            report.problems.append(Problem(f"{UNREADABLE} kept output", "outputs", path, detail=denied) if denied
                                   else Problem("corrupt kept output", "outputs", path, detail=why))


def _verify_assets(root: Path, report: Verification) -> None:
    """Hash every file extracted from a mesh archive (``assets/``) against its manifest."""
    for entry in scan(root / extracted.ASSETS_FOLDER):
        if not entry.is_dir(follow_symlinks=False):
            continue
        folder = Path(entry.path)
        report.assets += 1
        for rel, why in extracted.check_folder(folder):
            denied = cannot_open(folder / rel)
            kind = f"{UNREADABLE} extracted asset" if denied else "corrupt extracted asset"
            report.problems.append(Problem(kind, "assets", folder / rel, entry.name, denied or why))


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
                report.problems.append(_read_failed("blob", "truths", path, key, exc))
                continue
            if not ok:
                report.problems.append(Problem("corrupt blob", "truths", path, key,
                                               "content does not match its recorded SHA-256"))


def repair(root: Path, report: Verification) -> int:
    """Fix what :func:`verify` found; call it holding the writer lock. Returns problems fixed.

    Corrupt segments and jobs tables go to ``quarantine/`` (their rows are recomputed by the
    next run); rows whose blob is missing or corrupt are dropped and the blob quarantined, so
    the next run renders or postprocesses them again. A file the OS would not let sweep3d read
    (``unreadable …``) is left where it is, with its rows: it may be intact.
    """
    store = Store(root)
    fixed = 0
    problems = report.repairable  # not a file the OS would not let us read: it may be intact
    for problem in problems:
        if problem.kind in ("corrupt segment", "corrupt jobs table"):
            if store.quarantine(problem.path) is not None:
                fixed += 1
    for table in BLOB_TABLES:
        keys = {p.key for p in problems if p.table == table and p.key is not None}
        if keys:
            store.drop_rows(table, keys)
            for key in keys:
                blob = store.blob_path(key)
                if blob.exists():
                    store.quarantine(blob)
            fixed += len(keys)
    for problem in problems:  # a kept model output (the next run runs the model again) or a table's kept
        # file (its row then names none: its writer keeps it anew when it writes the row again)
        if problem.kind.startswith("corrupt kept ") and store.quarantine(problem.path) is not None:
            fixed += 1
    for name in {p.key for p in problems if p.kind == "corrupt extracted asset" and p.key is not None}:
        fixed += store.quarantine(root / extracted.ASSETS_FOLDER / name) is not None
    truths = {p.key for p in problems if p.table == "truths" and p.key is not None}
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


def store_files(folder: Path) -> Iterator[os.DirEntry]:
    """The files under ``folder`` at any depth, as the store wrote them: symbolic links (to a
    file or a folder, or ``folder`` itself one) are not the store's and are skipped, never followed."""
    if folder.is_symlink():
        return
    for entry in scan(folder):
        if entry.is_dir(follow_symlinks=False):
            yield from store_files(Path(entry.path))
        elif entry.is_file(follow_symlinks=False):
            yield entry


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


# -- compact -----------------------------------------------------------------------------------
@dataclass
class Compacted:
    table: str
    segments_before: int
    rows_before: int
    rows_after: int


def compact_table(store: Store, table: str) -> Compacted | None:
    """Merge every readable segment of ``table`` into one, dropping duplicate rows of a key
    (keeping the row the views show: the earliest ``created_at``, or the latest where the table's
    contract says the newest row counts). Call it holding the lock.

    The merged segment is written (atomically) first, then a record of the segments it replaces
    (from then on they are no longer listed); the replaced files stay on disk for
    ``SUPERSEDED_GRACE`` seconds so a reader that listed them just before can still read them.
    A reader sees the old segments, or old and merged ones (deduplicated by the views), or the
    merged one: never a gap. Returns None when there is nothing to merge.
    """
    store.sweep_superseded(table)
    if table == "predictions":  # merged, a segment lacking its evaluator's columns would read as NULLs
        evaluated_columns_lacking(store)
    paths = store.readable_segments(table)
    parts = [(p, store.read_segment(p)) for p in paths]
    parts = [(p, t) for p, t in parts if t is not None]
    if not parts:
        return None
    merged = pa.concat_tables([t for _, t in parts], promote_options="permissive")
    rows_before = merged.num_rows
    contract = contract_of(table)
    key = contract.key
    if "created_at" in merged.column_names:  # the row that counts first (merge "newest": the latest)
        order = "descending" if contract.merge == "newest" else "ascending"
        merged = merged.take(pc.sort_indices(merged, sort_keys=[("created_at", order)]))
    seen: set[str] = set()
    first = [i for i, k in enumerate(merged.column(key).to_pylist()) if not (k in seen or seen.add(k))]
    if len(parts) == 1 and len(first) == rows_before:
        return None
    merged = merged.take(pa.array(first, type=pa.int64()))
    name = segment_name()
    store.write_table_file(store.table_dir(table) / name, with_column_list(merged))
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
    """Files, rows, distinct keys and bytes per table, then blobs, each table's kept files (keys:
    those its rows name), temp files and quarantine."""
    store = Store(root, quarantine=False, warn=False)
    out = []
    for table in table_names():
        paths = store.segments(table)
        data = store.table(table, [contract_of(table).key])
        rows = data.num_rows if data is not None else 0
        keys = len(set(data.column(0).to_pylist())) if data is not None else 0
        out.append(TableStats(table, len(paths), rows, keys, sum(_size(p) for p in paths)))
    jobs = jobs_files(root)
    out.append(TableStats("jobs", len(jobs), sum(_rows(store, p) for p in jobs), len(jobs), sum(_size(p) for p in jobs)))
    blobs = [Path(e.path) for folder, e in _blob_files(root / "blobs") if blob_key(e.name, folder) is not None]
    out.append(TableStats("blobs", len(blobs), len(blobs), len(blobs), sum(_size(p) for p in blobs)))
    replaced = [store.table_dir(t) / n for t in table_names() for _, names, _ in store.superseded(t) for n in names]
    replaced = [p for p in replaced if p.is_file()]
    out.append(TableStats("compacted away", len(replaced), 0, 0, sum(_size(p) for p in replaced)))
    for contract in table_contracts():
        if contract.kept is not None:
            files = [Path(e.path) for e in store_files(root.joinpath(*contract.kept.folder)) if not _is_temp(e.name)]
            out.append(TableStats(f"kept {contract.kept.noun}s", len(files), len(files),
                                  len(kept_names(store, contract)), sum(_size(p) for p in files)))
    temp = [p for p in root.rglob(".*.tmp")] if root.is_dir() else []
    out.append(TableStats("temp files", len(temp), 0, 0, sum(_size(p) for p in temp)))
    quarantine = [p for p in (root / "quarantine").rglob("*") if p.is_file()] if (root / "quarantine").is_dir() else []
    out.append(TableStats("quarantine", len(quarantine), 0, 0, sum(_size(p) for p in quarantine)))
    return out


def jobs_files(root: Path) -> list[Path]:
    """The experiments' jobs files (``jobs/*.parquet``), by name."""
    return sorted(root / "jobs" / e.name for e in scan(root / "jobs") if e.name.endswith(".parquet")
                  and not e.name.startswith("."))


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


def _rows(store: Store, path: Path) -> int:
    data = store.read_segment(path, ["job"])
    return data.num_rows if data is not None else 0
