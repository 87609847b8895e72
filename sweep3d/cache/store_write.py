"""Writing the store's tables: whole Parquet files, atomically and with page checksums, and the
append-only segments a run adds a few seconds apart."""

from __future__ import annotations

import os
import time
import uuid
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import pyarrow as pa
import pyarrow.parquet as pq

from sweep3d.cache.columns import with_column_list
from sweep3d.cache.files import _as_write_error, _holds, _is_write_error, _unlink_quietly, atomic_write, segment_name

if TYPE_CHECKING:
    from sweep3d.cache.store import Store


class SegmentWrites:
    """:class:`~sweep3d.cache.store.Store`'s writes."""

    table_dir: Callable[[str], Path]  # the store's

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
