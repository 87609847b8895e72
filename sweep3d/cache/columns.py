"""A segment's columns: the list each one carries, and what its table's contract requires of one
that lists none (see :class:`~sweep3d.cache.contracts.TableContract`)."""

from __future__ import annotations

import json
from typing import Iterable

import pyarrow as pa

from sweep3d.cache.contracts import table_contract

#: Parquet metadata key of a segment listing the columns it was written with (a JSON list).
COLUMNS_METADATA = b"sweep3d.columns"
#: Columns a jobs file must have (what results join on).
JOBS_COLUMNS = ("pred_key",)


def required_columns(kind: str) -> tuple[str, ...]:
    """Columns every file of ``kind`` (a table's name, or ``jobs``) must have, of text: its key."""
    if kind == "jobs":
        return JOBS_COLUMNS
    contract = table_contract(kind)
    return (contract.key,) if contract is not None else ()


def table_columns(kind: str) -> tuple[str, ...]:
    """Columns every segment of the table ``kind`` has had since it was first written (none for
    a table no package declares)."""
    contract = table_contract(kind)
    return contract.columns if contract is not None else ()


def with_column_list(table: pa.Table) -> pa.Table:
    """``table`` with the list of its columns in its metadata, so a segment that later lacks one
    (a tool rewrote it without a column) reads as damaged rather than as rows with nulls."""
    metadata = {**(table.schema.metadata or {}), COLUMNS_METADATA: json.dumps(table.column_names).encode()}
    return table.replace_schema_metadata(metadata)


def check_column_list(table: pa.Table) -> bool:
    """Raise ValueError (a read error: the segment is damaged) when ``table`` lacks a column its
    metadata lists. Returns whether it lists its columns: one that does not (written before the
    list was kept, or stripped of it) is judged by its table's columns instead (:func:`table_columns`)."""
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
