"""``sweep3d cache compact`` (and a run's, for a crowded table): merge a table's segments into one,
keeping the row of each key that its contract says counts."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc

from sweep3d.cache.columns import with_column_list
from sweep3d.cache.contracts import contract_of
from sweep3d.cache.files import atomic_write, segment_name
from sweep3d.cache.store import Store
from sweep3d.cache.verification import evaluated_columns_lacking


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
