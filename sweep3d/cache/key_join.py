"""Look cache keys up among other keys, as Arrow string arrays, by sorting rather than hashing.

A rerun of 10⁶ cached jobs compares several key columns of 10⁶ rows each: the keys a stage
counts as cached, the blob states a child process took, the memo of verified blobs and the
rows' digests. A hash lookup (``pc.index_in``) costs about 0.5 s per pair at that size on one
core; most of these columns are sorted already (the memo is written sorted, the child lists in
order, :func:`sorted_keys` sorts the rest) or are the very same keys, and two sorted columns
of equal-width keys join by a binary search in tenths of that.

Keys are hex digests of one width, so a column is viewed as a numpy array of fixed-width byte
strings without a copy; a column of mixed widths (none a run makes, but any a caller passes)
falls back to Arrow's hash lookup, with the same answers.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

ABSENT = -1  # the position of a key that is not there


def sorted_keys(keys: Iterable[str] | pa.Array | pa.ChunkedArray) -> pa.Array:
    """``keys`` as an Arrow string array in ascending byte order (duplicates kept)."""
    array = _one_chunk(keys if isinstance(keys, (pa.Array, pa.ChunkedArray)) else pa.array(list(keys), pa.string()))
    fixed = _fixed_width(array)
    if fixed is None:
        return array.take(pc.sort_indices(array))
    if _ascending(fixed):
        return array
    data = np.sort(fixed)
    large = pa.types.is_large_string(array.type)  # the type it came with, and offsets that fit it
    offsets = np.arange(len(data) + 1, dtype=np.int64 if large else np.int32) * data.dtype.itemsize
    kind = pa.LargeStringArray if large else pa.StringArray
    return kind.from_buffers(len(data), pa.py_buffer(offsets), pa.py_buffer(data.view(np.uint8)))


def positions(query: pa.Array | pa.ChunkedArray, values: pa.Array | pa.ChunkedArray) -> np.ndarray:
    """The position in ``values`` of each key of ``query`` (its first, where it repeats), or
    :data:`ABSENT`; as ``pc.index_in(query, value_set=values)`` answers, without nulls."""
    query, values = _one_chunk(query), _one_chunk(values)
    if len(query) == 0 or len(values) == 0:
        return np.full(len(query), ABSENT, dtype=np.int64)
    asked, held = _fixed_width(query), _fixed_width(values)
    if asked is None or held is None or asked.dtype != held.dtype:
        found = pc.index_in(query, value_set=values)
        return pc.fill_null(found, ABSENT).to_numpy(zero_copy_only=False).astype(np.int64)
    if len(asked) == len(held) and _ascending(held, strictly=True) and np.array_equal(asked, held):
        return np.arange(len(asked), dtype=np.int64)  # the same distinct keys in the same order (a rerun's)
    order = None if _ascending(held) else np.argsort(held, kind="stable")  # stable: a repeat's first comes first
    held = held if order is None else held[order]
    asked_order = None if _ascending(asked) else np.argsort(asked)
    asked = asked if asked_order is None else asked[asked_order]
    at = np.minimum(np.searchsorted(held, asked), len(held) - 1)
    where = np.where(held[at] == asked, at if order is None else order[at], ABSENT).astype(np.int64)
    if asked_order is None:
        return where
    out = np.empty_like(where)
    out[asked_order] = where
    return out


def _one_chunk(array: pa.Array | pa.ChunkedArray) -> pa.Array:
    if isinstance(array, pa.ChunkedArray):
        return array.combine_chunks() if array.num_chunks != 1 else array.chunk(0)
    return array


def _fixed_width(array: pa.Array) -> np.ndarray | None:
    """``array``'s strings as a numpy array of fixed-width bytes (no copy), when they all have
    one width and none is null or holds a NUL byte (numpy's byte strings drop trailing NULs)."""
    if array.null_count or not (pa.types.is_string(array.type) or pa.types.is_large_string(array.type)):
        return None
    offset_type = np.int64 if pa.types.is_large_string(array.type) else np.int32
    _, offsets, data = array.buffers()
    ends = np.frombuffer(offsets, dtype=offset_type)[array.offset: array.offset + len(array) + 1]
    width = int(ends[1] - ends[0]) if len(array) else 0
    if width == 0 or int(ends[-1] - ends[0]) != width * len(array) or np.any(np.diff(ends) != width):
        return None
    raw = np.frombuffer(data, dtype=np.uint8)[ends[0]: ends[-1]]
    if not raw.all():  # a NUL byte: numpy would compare it away
        return None
    return raw.view(f"S{width}")


def _ascending(keys: np.ndarray, strictly: bool = False) -> bool:
    if len(keys) < 2:
        return True
    return bool(np.all(keys[1:] > keys[:-1]) if strictly else np.all(keys[1:] >= keys[:-1]))
