"""Blob integrity: the digest recorded in a blob's row, and reading a blob back safely.

Blobs are named by cache key, not by content, so the row that describes a blob records the
SHA-256 of its bytes when it is written; a reader compares against it. A blob that is missing,
does not match, or does not decode is reported as None, and the stage that needed it treats
it as never computed. One that is there but cannot be read (permission denied, an I/O error) is
not damaged: it is a :class:`~sweep3d.cache.store.StoreReadError` naming it with the OS's reason,
and nothing is discarded or made again over it.

A run also checks the blobs it counts as cached (:func:`damaged_blobs`), so a damaged one is
recomputed even when nothing downstream reads it again. What it verified is remembered in
``verified/<table>.parquet`` under the store, by file state, so a rerun hashes only blobs whose
file changed since (see :func:`damaged_blobs` for what that does and does not catch); a run's
passes add the blobs they write (:func:`remember_verified`), so the first rerun hashes none.
"""

from __future__ import annotations

import hashlib
import io
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Literal

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from sweep3d.cache.key_join import positions, sorted_keys
from sweep3d.cache.store import (
    DIGEST_COLUMN,
    KEY_COLUMN,
    READ_ERRORS,
    Store,
    StoreReadError,
    StoreWriteError,
    read_parquet,
    store_error,
)

#: Columns of a ``verified/<table>.parquet`` memo: a blob's key, its file state when it was last
#: hashed, and the digest it had then.
MEMO_SCHEMA = pa.schema([("key", pa.string()), ("size", pa.int64()), ("mtime_ns", pa.int64()),
                         ("ctime_ns", pa.int64()), ("inode", pa.int64()), (DIGEST_COLUMN, pa.string())])


def sha256_bytes(data: bytes) -> str:
    """Hex SHA-256 of ``data``: the digest recorded in a blob's row."""
    return hashlib.sha256(data).hexdigest()


def blob_is_intact(data: bytes, digests: set[str]) -> bool:
    """True when ``data`` matches one of its rows' digests, or (none recorded) decodes as an image."""
    if digests:
        return sha256_bytes(data) in digests
    return decode_image(data) is not None


def decode_image(data: bytes) -> np.ndarray | None:
    """PNG bytes as float32 (H, W, 3) in [0, 1], or None when they do not decode."""
    from sweep3d.core import from_uint8

    pixels = decode_pixels(data)
    return None if pixels is None else from_uint8(pixels)


def decode_pixels(data: bytes) -> np.ndarray | None:
    """PNG bytes as their uint8 (H, W, 3) pixels, or None when they do not decode."""
    from sweep3d.core import decode_png8

    try:
        return decode_png8(io.BytesIO(data))
    except Exception:  # noqa: BLE001  (any decoder failure means a damaged blob)
        return None


def unreadable_blob(exc: OSError) -> StoreReadError:
    """One line for a blob the OS will not let this process read (its permissions, an I/O error):
    unreadable, not damaged, so it is neither discarded nor made again over what cannot be read."""
    return StoreReadError(f"{store_error(exc, 'read')} (a blob that cannot be read is not damaged: sweep3d leaves "
                          "it, and its results, as they are)")


def read_blob(path: Path) -> bytes | None:
    """The bytes of the blob at ``path``; None when there is none.

    Raises:
        StoreReadError: it is there but cannot be read (permission denied, an I/O error).
    """
    try:
        return path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise unreadable_blob(exc) from None


def load_image(store: Store, key: str, digests: set[str] | None) -> np.ndarray | None:
    """The blob ``key`` as float32 (H, W, 3) in [0, 1]; None if it is missing or damaged.

    Raises:
        StoreReadError: it cannot be read (see :func:`read_blob`).
    """
    from sweep3d.core import from_uint8

    pixels = load_pixels(store, key, digests)
    return None if pixels is None else from_uint8(pixels)


def load_pixels(store: Store, key: str, digests: set[str] | None) -> np.ndarray | None:
    """The blob ``key`` as its uint8 (H, W, 3) pixels; None if it is missing or damaged.

    Args:
        digests: the SHA-256 digests its rows recorded (empty or None: only check it decodes).

    Raises:
        StoreReadError: it cannot be read (see :func:`read_blob`).
    """
    data = read_blob(store.blob_path(key))
    if data is None:
        return None
    if digests and sha256_bytes(data) not in digests:
        return None
    return decode_pixels(data)


def load_pass(store: Store, truth_key: str, name: str, digests: set[str] | None = None) -> np.ndarray | None:
    """A truth pass's array ("mask": bool (H, W), "depth": float32 (H, W)) from its blob under
    ``truth_key``; None if it is missing, does not decode, or (``digests`` given and not empty)
    matches none of the digests its rows recorded (its row is then dropped by the caller, and the
    pass rendered again). A blob that cannot be read raises :class:`StoreReadError`."""
    from sweep3d.core import BLOB_SUFFIX, decode_depth, decode_mask

    data = read_blob(store.blob_path(truth_key, BLOB_SUFFIX[name]))
    if data is None:
        return None
    try:
        if digests and sha256_bytes(data) not in digests:
            return None
        return decode_mask(data) if name == "mask" else decode_depth(data)
    except Exception:  # noqa: BLE001  (missing, truncated or not an image/archive: the same repair)
        return None


@dataclass(frozen=True)
class Verified:
    """A blob's file state (size, mtime, ctime, inode) when it was hashed, and its digest then."""

    state: tuple[int, int, int, int]
    digest: str


def damaged_blobs(store: Store, table: str, keys: Iterable[str]) -> set[str]:
    """The ``keys`` of ``table`` whose blob no longer matches a digest its rows recorded (or, with
    none recorded, no longer decodes); missing blobs are left to the caller.

    A blob is hashed only when its file state differs from the one under which it was last
    verified (remembered in ``verified/<table>.parquet``, rewritten atomically). The state holds
    the change time, which every write through the file system moves on and which ``touch`` or
    ``os.utime`` cannot set back, so a blob edited in place with its size and mtime restored is
    still hashed again. Not caught here: damage that bypasses the file system (bit rot on the
    disk, writes to the raw device) or a clock set back by an administrator; stage reads still
    check digests, and ``sweep3d cache verify`` hashes every blob. A copied store hashes each
    blob once (new inodes). Call it holding the writer lock.

    A rerun of a million cached jobs costs one ``stat`` per blob (taken ahead by a child, see
    :mod:`.snapshot`): the keys, the memo, the blob states and the rows are compared as sorted
    Arrow columns (:mod:`.key_join`), never as a dict per blob.
    """
    keys = sorted_keys(keys if isinstance(keys, (set, frozenset)) else set(keys))  # distinct, in byte order
    rows = store.table(table, [KEY_COLUMN[table], DIGEST_COLUMN])
    recorded = _recorded(rows, table)
    memo = _read_memo_table(store, table)
    states = file_states(store, keys)
    in_memo, in_rows = positions(keys, memo.column("key")), positions(keys, recorded["keys"])
    trusted = _trusted(keys, states, memo, in_memo, recorded, in_rows, rows, table)
    damaged: set[str] = set()
    fresh: dict[str, Verified] = {}
    again = keys.filter(pa.array(~trusted & (states[:, 0] != MISSING))).to_pylist()  # changed, new
    digests = _digests_of(rows, table, again)
    for key in again:
        outcome = check_blob(store.blob_file(key), digests.get(key, set()), None)
        if outcome == "damaged":
            damaged.add(key)
        elif isinstance(outcome, Verified):
            fresh[key] = outcome
    if not fresh and not damaged and (in_rows >= 0).all() and np.count_nonzero(in_memo >= 0) == memo.num_rows:
        return damaged  # nothing hashed again, every memo entry a recorded key's: no entry to add or drop
    kept = memo.filter(pc.and_(pc.is_in(memo.column("key"), value_set=recorded["keys"]),
                               pc.invert(pc.is_in(memo.column("key"), value_set=pa.array(sorted(damaged | set(fresh)),
                                                                                          type=pa.string())))))
    if fresh or kept.num_rows != memo.num_rows:
        store.write_table_file(memo_path(store, table), _memo_rows(kept, fresh))
    return damaged


MISSING = -1  # a file state's size when the file is not there
_UNREADABLE = -2  # ... when stat failed otherwise


def file_states(store: Store, keys: pa.Array | list[str]) -> np.ndarray:
    """(size, mtime_ns, ctime_ns, inode) of each key's blob as an int64 array (n, 4); the size is
    :data:`MISSING` for a blob that is not there and negative for one that cannot be stat'ed.

    Read from the store's snapshot where a run took one (:meth:`Store.snapshot_states`: a child
    stat'ed every blob while the run planned); the keys it lacks are stat'ed here."""
    snapshot = store.state_snapshot
    arrow = keys if isinstance(keys, pa.Array) else pa.array(keys, type=pa.string())
    taken = snapshot.states(arrow) if snapshot is not None else None
    if taken is None:
        return _stat_states(store, arrow.to_pylist() if isinstance(keys, pa.Array) else keys)
    states, found = taken
    lacking = np.flatnonzero(~found)
    if len(lacking):
        states[lacking] = _stat_states(store, arrow.take(pa.array(lacking)).to_pylist())
    return states


def _stat_states(store: Store, keys: list[str]) -> np.ndarray:
    """:func:`file_states` by one ``stat`` per key. At 10⁶ blobs this is a run's largest single
    cost after the ``stat`` calls themselves, so the paths are made in one comprehension and the
    states gathered into one flat list."""
    blob_file = store.blob_file
    flat: list[int] = []
    extend = flat.extend
    stat = os.stat
    for path in [blob_file(key) for key in keys]:
        try:
            st = stat(path)
            extend((st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino))
        except FileNotFoundError:
            extend((MISSING, 0, 0, 0))
        except OSError:
            extend((_UNREADABLE, 0, 0, 0))
    return np.array(flat, dtype=np.int64).reshape(len(keys), 4)


def _recorded(rows: pa.Table | None, table: str) -> dict[str, pa.Array]:
    """What ``table``'s rows recorded: each row's key, and its digest (null where none)."""
    if rows is None:
        return {"keys": pa.array([], type=pa.string()), "digests": pa.array([], type=pa.string())}
    keys = rows.column(KEY_COLUMN[table])
    if DIGEST_COLUMN not in rows.column_names:
        return {"keys": keys, "digests": pa.nulls(len(keys), type=pa.string())}
    digests = rows.column(DIGEST_COLUMN)
    return {"keys": keys, "digests": pc.if_else(pc.equal(pc.fill_null(digests, ""), ""), None, digests)}


def _trusted(keys: pa.Array, states: np.ndarray, memo: pa.Table, in_memo: np.ndarray,
             recorded: dict[str, pa.Array], in_rows: np.ndarray, rows: pa.Table | None, table: str) -> np.ndarray:
    """Per key, whether its memo entry vouches for it: same file state, and its digest one its
    rows recorded (or they recorded none). ``in_memo``, ``in_rows``: each key's position in the
    memo and among the rows (its first), or -1."""
    found = in_memo >= 0
    if not found.any():
        return found
    at = np.where(found, in_memo, 0)
    remembered = np.stack([memo.column(c).to_numpy()[at] for c in ("size", "mtime_ns", "ctime_ns", "inode")], axis=1)
    same = found & (remembered == states).all(axis=1)
    digest = pc.take(memo.column(DIGEST_COLUMN), pa.array(at))
    first = pc.take(recorded["digests"], pa.array(in_rows, mask=in_rows < 0))  # the key's first row's
    trusted = same & _flags(pc.equal(digest, first))
    unsure = np.flatnonzero(same & ~trusted)  # another row's digest, or none recorded: as the rows say
    if len(unsure):
        recorded_digests = _digests_of(rows, table, keys.take(pa.array(unsure)).to_pylist())
        for i in unsure.tolist():
            digests = recorded_digests.get(keys[i].as_py(), set())
            trusted[i] = digest[i].as_py() in digests or not digests
    return trusted


def _flags(values: pa.Array) -> np.ndarray:
    return pc.fill_null(values, False).to_numpy(zero_copy_only=False).astype(bool)


def _digests_of(rows: pa.Table | None, table: str, keys: list[str]) -> dict[str, set[str]]:
    """The digests the rows of ``keys`` recorded (for blobs hashed again)."""
    out: dict[str, set[str]] = {}
    if rows is None or DIGEST_COLUMN not in rows.column_names or not keys:
        return out
    mine = rows.filter(pc.is_in(rows.column(KEY_COLUMN[table]), value_set=pa.array(keys, type=pa.string())))
    for key, digest in zip(mine.column(KEY_COLUMN[table]).to_pylist(), mine.column(DIGEST_COLUMN).to_pylist()):
        if digest:
            out.setdefault(key, set()).add(digest)
    return out


def _read_memo_table(store: Store, table: str) -> pa.Table:
    """The memo of ``table`` (empty when there is none or it does not read: every blob is then
    hashed again and the memo rewritten; nothing to quarantine)."""
    try:
        memo = read_parquet(memo_path(store, table), verify=True)
        return memo.select(MEMO_SCHEMA.names).cast(MEMO_SCHEMA)
    except (*READ_ERRORS, KeyError):
        return MEMO_SCHEMA.empty_table()


def _memo_rows(kept: pa.Table, fresh: dict[str, Verified]) -> pa.Table:
    """``kept`` memo rows and ``fresh`` entries as one memo, sorted by key."""
    keys = sorted(fresh)
    added = pa.table({"key": keys, **{name: [fresh[k].state[i] for k in keys]
                                      for i, name in enumerate(("size", "mtime_ns", "ctime_ns", "inode"))},
                      DIGEST_COLUMN: [fresh[k].digest for k in keys]}, schema=MEMO_SCHEMA)
    both = pa.concat_tables([kept.cast(MEMO_SCHEMA), added])
    return both.take(pc.sort_indices(both, sort_keys=[("key", "ascending")]))


def check_blob(path: str, digests: set[str], last: Verified | None) -> Verified | Literal["missing", "damaged"]:
    """The blob at ``path`` checked against ``digests``: a :class:`Verified` when it is intact.

    ``last`` (its memo entry) spares the hashing when its file state has not changed since and
    its digest is still a recorded one.

    Raises:
        StoreReadError: it is there but cannot be read (permission denied, an I/O error): that is
            not damage, and what cannot be read is not discarded and made again.
    """
    try:
        stat = os.stat(path)
        state = (stat.st_size, stat.st_mtime_ns, stat.st_ctime_ns, stat.st_ino)
        if last is not None and last.state == state and (last.digest in digests or not digests):
            return last
        with open(path, "rb") as fh:
            data = fh.read()
    except FileNotFoundError:
        return "missing"
    except OSError as exc:
        raise unreadable_blob(exc) from None
    digest = sha256_bytes(data)
    intact = digest in digests if digests else decode_image(data) is not None
    return Verified(state, digest) if intact else "damaged"


def verified_now(path: str) -> Verified | None:
    """The blob at ``path`` as it is now: its file state, taken before its bytes are read (as
    :func:`check_blob` takes it, so that a later write shows as another state), and their digest;
    None when it cannot be read."""
    try:
        with open(path, "rb") as fh:
            st = os.fstat(fh.fileno())
            data = fh.read()
    except OSError:
        return None
    return Verified((st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino), sha256_bytes(data))


def remember_verified(store: Store, table: str, fresh: dict[str, Verified]) -> None:
    """Add ``fresh`` to the memo of ``table``: blobs a stage has just written, each read back
    (:func:`verified_now`) with the digest its row records, so that the first rerun hashes none of
    them again (:func:`damaged_blobs`). A memo that cannot be written is only hashed again."""
    if not fresh:
        return
    memo = _read_memo_table(store, table)
    kept = memo.filter(pc.invert(pc.is_in(memo.column("key"), value_set=pa.array(sorted(fresh), type=pa.string()))))
    try:
        store.write_table_file(memo_path(store, table), _memo_rows(kept, fresh))
    except StoreWriteError:
        pass


def memo_path(store: Store, table: str) -> Path:
    """Where the blobs of ``table`` that runs verified are remembered."""
    return store.root / "verified" / f"{table}.parquet"
