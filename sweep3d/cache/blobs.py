"""Blob integrity: the digest recorded in a blob's row, and reading a blob back safely.

Blobs are named by cache key, not by content, so the row that describes a blob records the
SHA-256 of its bytes when it is written; a reader compares against it. A blob that is missing,
does not match, or does not decode is reported as None, and the stage that needed it treats
it as never computed.

A run also checks the blobs it counts as cached (:func:`damaged_blobs`), so a damaged one is
recomputed even when nothing downstream reads it again. What it verified is remembered in
``verified/<table>.parquet`` under the store, by file state, so a rerun hashes only blobs whose
file changed since (see :func:`damaged_blobs` for what that does and does not catch).
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
import pyarrow.parquet as pq

from sweep3d.cache.store import DIGEST_COLUMN, READ_ERRORS, Store

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
    from sweep3d.pixels import decode_png

    try:
        return decode_png(io.BytesIO(data))  # type: ignore[arg-type]  (PIL opens file objects too)
    except Exception:  # noqa: BLE001  (any decoder failure means a damaged blob)
        return None


def load_image(store: Store, key: str, digests: set[str] | None) -> np.ndarray | None:
    """The blob ``key`` as float32 (H, W, 3) in [0, 1]; None if it is missing or damaged.

    Args:
        digests: the SHA-256 digests its rows recorded (empty or None: only check it decodes).
    """
    try:
        data = store.blob_path(key).read_bytes()
    except OSError:
        return None
    if digests and sha256_bytes(data) not in digests:
        return None
    return decode_image(data)


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
    """
    recorded = store.digests(table)
    memo = read_memo(store, table)
    damaged: set[str] = set()
    fresh: dict[str, Verified] = {}
    for key in keys:
        verdict = check_blob(store.blob_file(key), recorded.get(key, set()), memo.get(key))
        if verdict == "damaged":
            damaged.add(key)
        elif isinstance(verdict, Verified) and memo.get(key) != verdict:
            fresh[key] = verdict
    kept = {k: v for k, v in memo.items() if k in recorded and k not in damaged}
    if fresh or len(kept) != len(memo):
        write_memo(store, table, kept | fresh)
    return damaged


def check_blob(path: str, digests: set[str], last: Verified | None) -> Verified | Literal["missing", "damaged"]:
    """The blob at ``path`` checked against ``digests``: a :class:`Verified` when it is intact.

    ``last`` (its memo entry) spares the hashing when its file state has not changed since and
    its digest is still a recorded one.
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
    except OSError:  # an I/O error reading it back: as good as damaged
        return "damaged"
    digest = sha256_bytes(data)
    intact = digest in digests if digests else decode_image(data) is not None
    return Verified(state, digest) if intact else "damaged"


def memo_path(store: Store, table: str) -> Path:
    """Where the blobs of ``table`` that runs verified are remembered."""
    return store.root / "verified" / f"{table}.parquet"


def read_memo(store: Store, table: str) -> dict[str, Verified]:
    """Key → :class:`Verified` for ``table``; empty when there is no memo or it does not read
    (then every blob is hashed again and the memo rewritten: nothing to quarantine)."""
    try:
        data = pq.read_table(memo_path(store, table), page_checksum_verification=True).to_pydict()
        rows = zip(data["key"], data["size"], data["mtime_ns"], data["ctime_ns"], data["inode"], data[DIGEST_COLUMN])
        return {key: Verified((size, mtime, ctime, inode), digest) for key, size, mtime, ctime, inode, digest in rows}
    except (*READ_ERRORS, KeyError):
        return {}


def write_memo(store: Store, table: str, entries: dict[str, Verified]) -> None:
    """Replace the memo of ``table`` with ``entries`` (atomically: temp file, fsync, rename)."""
    keys = sorted(entries)
    columns = {"key": keys, **{name: [entries[k].state[i] for k in keys]
                               for i, name in enumerate(("size", "mtime_ns", "ctime_ns", "inode"))},
               DIGEST_COLUMN: [entries[k].digest for k in keys]}
    store.write_table_file(memo_path(store, table), pa.table(columns, schema=MEMO_SCHEMA))
