"""Reading the store's tables: their segments, each checked once (page checksums, its columns
against its table's contract), their keys, and DuckDB views deduplicated by each contract's key
and merge rule."""

from __future__ import annotations

import errno
import json
import os
import stat
from pathlib import Path
from typing import Any, Callable, Collection, Iterable

import duckdb
import pyarrow as pa

from sweep3d.cache.columns import check_column_list, lacking_columns, required_columns, table_columns
from sweep3d.cache.contracts import contract_of, table_contracts, table_names
from sweep3d.cache.files import READ_ERRORS, _first_line, _is_segment_name, read_parquet, scan
from sweep3d.cache.query import _sql_str
from sweep3d.cache.store_blobs import DIGEST_COLUMN

SUPERSEDED_GRACE = 600.0  # seconds a compaction keeps the segments it merged, for readers that listed them


class SegmentReads:
    """:class:`~sweep3d.cache.store.Store`'s reads."""

    root: Path
    table_dir: Callable[[str], Path]  # the store's
    jobs_path: Callable[[str], Path]
    quarantine_bad: bool
    _checked: dict[tuple[str, int, int], list[str]]  # (path, size, mtime) read whole once -> columns
    _unlisted: set[tuple[str, int, int]]  # ... of those, the segments listing no columns
    _condemned: set[tuple[str, int, int]]  # segments require_columns found damaged
    _bad: dict[str, str]  # unreadable files already reported -> why
    _keys: dict[str, tuple[tuple, frozenset[str]]]  # table -> (segment state, its keys)
    _report_bad: Callable[..., None]  # the store's damage control

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


    def read_segment(self, path: Path, columns: list[str] | None = None) -> pa.Table | None:
        """One segment (only the ``columns`` it has, when given), or None when it cannot be read.

        A segment is read whole, with its page checksums verified and its columns checked
        (its key, of text; those it lists, else its contract's columns), the first time this
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
        or, listing no columns of its own (``listed``), it lacks one of its contract's columns."""
        folder = path.parent
        kind = folder.name if folder.parent == self.root / "tables" or folder == self.root / "jobs" else None
        for column in required_columns(kind) if kind else ():
            if column not in schema.names:
                return f"its columns are not the {kind} table's: it has no {column} column"
            if not pa.types.is_string(schema.field(column).type):
                return f"its columns are not the {kind} table's: its {column} is {schema.field(column).type}, not text"
        if kind == "jobs" or listed:
            return ""
        return lacking_columns(schema.names, table_columns(kind) if kind else (), f"every {kind} row has")

    def require_columns(self, table: str, columns: Iterable[str], keys: Collection[str], whose: str) -> list[Path]:
        """Segments of ``table`` that hold a row of one of ``keys`` but lack one of ``columns``:
        what every row of those keys has (a prediction, its evaluator's columns, which
        its table's contract cannot know). Each is reported as damaged (``whose`` columns it
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
        for path, st in self._stats(table):
            ident = (str(path), st.st_size, st.st_mtime_ns)
            if ident not in self._checked:
                self.read_segment(path, [contract_of(table).key])  # checks it whole, once per store object
            if ident in self._unlisted and ident in self._checked and ident not in self._condemned:
                out.append((path, ident))
        return out

    def _holds_any(self, path: Path, table: str, keys: Collection[str]) -> bool:
        """Whether the segment at ``path`` holds a row of one of ``keys``."""
        data = self.read_segment(path, [contract_of(table).key])
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
        return [path for path, _ in self._read_all(table, [contract_of(table).key])]

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
        column = contract_of(table).key
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
        return tuple((str(path), st.st_size, st.st_mtime_ns, st.st_ino) for path, st in self._stats(table))

    def _stats(self, table: str) -> list[tuple[Path, os.stat_result]]:
        """Each segment of ``table`` with its ``stat``; one gone meanwhile (compacted away) is left out."""
        out = []
        for path in self.segments(table):
            try:
                out.append((path, path.stat()))
            except OSError:
                continue
        return out

    def column_map(self, table: str, column: str) -> dict[str, Any]:
        """Key → ``column`` of its first row (the row the views show), for keys that have one."""
        key = contract_of(table).key
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
        key = contract_of(table).key
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
        files = {table: segments for table in table_names() if (segments := self.readable_segments(table))}
        jobs_path = self.jobs_path(experiment) if experiment is not None else None
        if jobs_path is not None and self.read_segment(jobs_path, ["pred_key"]) is not None:
            files["jobs"] = [jobs_path]
        return files

    def connect(self, experiment: str | None = None,
                files: dict[str, list[Path]] | None = None) -> duckdb.DuckDBPyConnection:
        """An in-memory DuckDB connection with views over this store's Parquet files.

        Views: one per declared table (deduplicated by its contract's key: a key's first row, or
        its newest where the contract says so), and when ``experiment`` has a plan, ``jobs`` (its
        latest plan). Storage only: how
        they join into ``results``, and what counts, is the aggregate stage's
        (``sweep3d.results.base_views``), which adds its views on top
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
        con.execute("SET parquet_metadata_cache = true")
        for contract in table_contracts():
            if contract.name in files:
                listing = ", ".join(_sql_str(str(p)) for p in files[contract.name])
                con.execute(
                    f"CREATE VIEW {contract.name} AS SELECT * FROM read_parquet([{listing}], union_by_name = true) "
                    f"QUALIFY row_number() OVER (PARTITION BY {contract.key} ORDER BY {contract.row_order}) = 1"
                )
        if "jobs" in files:
            con.execute(f"CREATE VIEW jobs AS SELECT * FROM read_parquet({_sql_str(str(files['jobs'][0]))})")
        return con
