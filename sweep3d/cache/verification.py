"""``sweep3d cache verify``: re-read and re-hash what the store holds; change nothing.

Blobs are named by cache key, not by content, so a blob's integrity is checked against the
SHA-256 its row recorded when it was written (rows from before digests existed fall back to
"the PNG decodes"); so are a model's kept outputs (``outputs/``, their digest in the file) and the
meshes extracted from archives (``assets/``, their digests in the folder's manifest), and a
declared table's kept files by its contract's check. A segment is corrupt when it fails to read
with its page checksums verified, or lacks a column its rows always have (its table's, or for
predictions their evaluator's, as the plans in ``jobs/`` record it).
"""

from __future__ import annotations

import errno
import hashlib
import os
from dataclasses import dataclass, field
from pathlib import Path

from sweep3d.cache import digested, extracted
from sweep3d.cache.blobs import blob_is_intact
from sweep3d.cache.contracts import KeptFiles, TableContract, contract_of, table_contracts, table_names
from sweep3d.cache.files import scan, store_files
from sweep3d.cache.store import Store
from sweep3d.cache.store_blobs import BLOB_TABLES, TRUTH_BLOBS
from sweep3d.core import read_record


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


def jobs_files(root: Path) -> list[Path]:
    """The experiments' jobs files (``jobs/*.parquet``), by name."""
    return sorted(root / "jobs" / e.name for e in scan(root / "jobs") if e.name.endswith(".parquet")
                  and not e.name.startswith("."))
