"""The content-addressed store: blobs by key, append-only Parquet segments, DuckDB views.

Layout under the store root::

    blobs/ab/abcdef….png          one file per key (renders and post-processed images)
    tables/<table>/<seg>.parquet  append-only row segments (renders, images, predictions, runs)
    jobs/<experiment>.parquet     the latest plan of each experiment (its jobs and their keys)
    lock                          held by the one process that writes

Every write is a temp file plus an atomic rename, so a killed run leaves either a whole file
or none: rerunning recomputes only what no complete row records.
"""

from __future__ import annotations

import fcntl
import os
import time
import uuid
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterator

import duckdb
import pyarrow as pa
import pyarrow.parquet as pq

from sweep3d.errors import StoreBusyError, UserError

TABLES = ("renders", "images", "predictions", "runs")
KEY_COLUMN = {"renders": "render_key", "images": "image_key", "predictions": "pred_key", "runs": "run_id"}


class Store:
    """A store rooted at ``root``; cheap to construct, creates directories on first write."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    # -- paths -------------------------------------------------------------------------------
    def blob_path(self, key: str, ext: str = "png") -> Path:
        return self.root / "blobs" / key[:2] / f"{key}.{ext}"

    def table_dir(self, table: str) -> Path:
        return self.root / "tables" / table

    def jobs_path(self, experiment: str) -> Path:
        return self.root / "jobs" / f"{safe_filename(experiment)}.parquet"

    def report_path(self, experiment: str, suffix: str = ".html") -> Path:
        """Where an experiment's report files go by default: ``reports/<experiment><suffix>``."""
        return self.root / "reports" / f"{safe_filename(experiment)}{suffix}"

    def tmp_dir(self) -> Path:
        path = self.root / "tmp"
        path.mkdir(parents=True, exist_ok=True)
        return path

    def ensure_writable(self) -> None:
        """Create the store root or fail with a clear message (an unwritable store is a user error)."""
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            probe = self.root / f".probe-{os.getpid()}"
            probe.write_bytes(b"")
            probe.unlink()
        except OSError as exc:
            raise UserError(
                f"store {self.root} is not writable ({exc.strerror}); set experiment.store to a writable folder"
            ) from None

    # -- writes ------------------------------------------------------------------------------
    def write_table_file(self, path: Path, table: pa.Table) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
        pq.write_table(table, tmp, compression="zstd")
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)

    def append(self, table: str, rows: list[dict[str, Any]], schema: pa.Schema | None = None) -> Path | None:
        """Write ``rows`` as one new segment of ``table``; returns its path (None if no rows)."""
        if not rows:
            return None
        data = pa.Table.from_pylist(rows, schema=schema)
        name = f"{time.time_ns():020d}-{os.getpid()}-{uuid.uuid4().hex[:8]}.parquet"
        path = self.table_dir(table) / name
        self.write_table_file(path, data)
        return path

    def segment_writer(self, table: str, schema: pa.Schema | None = None, every: float = 3.0,
                       max_rows: int = 64) -> "SegmentWriter":
        return SegmentWriter(self, table, schema, every, max_rows)

    # -- reads -------------------------------------------------------------------------------
    def segments(self, table: str) -> list[Path]:
        directory = self.table_dir(table)
        if not directory.is_dir():
            return []
        return sorted(p for p in directory.glob("*.parquet") if not p.name.startswith("."))

    def keys(self, table: str) -> set[str]:
        """Every key with a complete row in ``table``."""
        files = self.segments(table)
        if not files:
            return set()
        column = KEY_COLUMN[table]
        keys: set[str] = set()
        for path in files:
            keys.update(pq.read_table(path, columns=[column]).column(column).to_pylist())
        return keys

    def connect(self, experiment: str | None = None) -> duckdb.DuckDBPyConnection:
        """An in-memory DuckDB connection with views over this store's Parquet files.

        Views: ``renders``, ``images``, ``predictions``, ``runs`` (deduplicated by key), and when
        ``experiment`` has a plan, ``jobs`` (its latest plan) and ``results`` (jobs ⨝ predictions),
        with the aggregate views over ``results`` (see :mod:`sweep3d.stages.aggregate.views`).
        """
        con = duckdb.connect()
        for table in TABLES:
            files = self.segments(table)
            key = KEY_COLUMN[table]
            if files:
                listing = ", ".join(_sql_str(str(p)) for p in files)
                con.execute(
                    f"CREATE VIEW {table} AS SELECT * FROM read_parquet([{listing}], union_by_name = true) "
                    f"QUALIFY row_number() OVER (PARTITION BY {key} ORDER BY created_at) = 1"
                )
        if experiment is not None and self.jobs_path(experiment).exists():
            jobs = _sql_str(str(self.jobs_path(experiment)))
            con.execute(f"CREATE VIEW jobs AS SELECT * FROM read_parquet({jobs})")
            if self.segments("predictions"):
                con.execute(
                    "CREATE VIEW results AS SELECT j.*, p.* EXCLUDE (pred_key, image_key, created_at) "
                    "FROM jobs j JOIN predictions p USING (pred_key)"
                )
        from sweep3d.stages.aggregate import register_views  # the report's aggregates, as views

        register_views(con)
        return con

    # -- locking -----------------------------------------------------------------------------
    @contextmanager
    def lock(self, wait: float = 0.0) -> Iterator[None]:
        """Hold the store's writer lock; readers never take it.

        Raises:
            StoreBusyError: if another process holds it for longer than ``wait`` seconds.
        """
        self.ensure_writable()
        fh = open(self.root / "lock", "a+")
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
            yield
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


def safe_filename(name: str) -> str:
    """``name`` with every character outside letters, digits, ``-_.`` replaced by ``_``."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def utc_now() -> datetime:
    """Now, in UTC, as a naive timestamp (tz-aware ones would need pytz to read back through DuckDB)."""
    return datetime.now(timezone.utc).replace(tzinfo=None)


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temp file in the same folder and a rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _sql_str(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"
