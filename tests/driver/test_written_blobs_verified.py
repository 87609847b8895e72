"""The blobs a pass writes enter the memo of verified blobs as they are written, so the first
rerun hashes none of them (``driver.loop._Pass._written``), and damage after is still found."""

from __future__ import annotations

import os
import time
from pathlib import Path

from sweep3d.cache import BLOB_TABLES
from sweep3d.cache.blobs import damaged_blobs, memo_path, remember_verified, sha256_bytes, verified_now
from sweep3d.cache.store import Store
from tests.helpers import HashCounter, render_row


def test_a_run_s_blobs_are_remembered_as_verified(tiny_run: Path, monkeypatch) -> None:
    """The tiny run's own store (a copy has new inodes: hashed once), looked at without a change."""
    store = Store(tiny_run / "store")
    hashed = HashCounter(monkeypatch)
    keys = {table: {k for k in store.keys(table) if store.has_blob(k)} for table in BLOB_TABLES}
    assert all(keys.values()) and all(memo_path(store, t).exists() for t in BLOB_TABLES)
    for table in BLOB_TABLES:
        assert damaged_blobs(store, table, keys[table]) == set()
    assert hashed.calls == 0, "the run that wrote them remembered them"


def test_a_blob_changed_after_it_was_remembered_is_hashed_and_found(tmp_path: Path, monkeypatch) -> None:
    store = Store(tmp_path / "store")
    keys = {f"{i:02x}" * 32 for i in range(3)}
    for key in keys:
        path = store.blob_path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(key.encode())
        store.append("renders", [render_row(key, digest=sha256_bytes(key.encode()))])
        remember_verified(store, "renders", {key: verified_now(str(path))})
    hashed = HashCounter(monkeypatch)
    assert damaged_blobs(store, "renders", keys) == set() and hashed.calls == 0
    time.sleep(0.05)  # the flip's change time a clock tick or more after the write's
    flipped = store.blob_path(min(keys))
    st = flipped.stat()
    data = bytearray(flipped.read_bytes())
    data[len(data) // 2] ^= 0xFF
    flipped.write_bytes(bytes(data))
    os.utime(flipped, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert damaged_blobs(store, "renders", keys) == {min(keys)} and hashed.calls == 1


def test_an_entry_is_the_file_as_read_and_replaces_the_key_s_old_one(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    path = store.blob_path("ab" * 32)
    path.parent.mkdir(parents=True)
    path.write_bytes(b"one")
    first = verified_now(str(path))
    assert first is not None and first.state[0] == 3
    remember_verified(store, "renders", {"ab" * 32: first})
    path.write_bytes(b"other")
    second = verified_now(str(path))
    assert second is not None and second.digest != first.digest and second.state != first.state
    remember_verified(store, "renders", {"ab" * 32: second})
    memo = store.read_segment(memo_path(store, "renders"))
    assert memo.column("key").to_pylist() == ["ab" * 32] and memo.column("sha256").to_pylist() == [second.digest]
    assert verified_now(str(tmp_path / "absent.png")) is None
