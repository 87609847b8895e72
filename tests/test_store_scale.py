"""What makes a rerun of a million cached jobs cheap keeps the store's answers: blobs found by a
listing are the blobs a check per key finds, remembered keys follow the segments, and the blob
memo compared as columns vouches for exactly what it vouched for before."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

import sweep3d.cache.store as store_module
from sweep3d.cache.blobs import damaged_blobs, sha256_bytes
from sweep3d.cache.store import Store, atomic_write
from sweep3d.pixels import encode_png
from tests.test_reliability import HashCounter, add_render, render_row


def test_a_listing_finds_the_blobs_a_check_per_key_finds(tmp_path: Path, monkeypatch) -> None:
    store = Store(tmp_path)
    keys = [f"{i:040x}" for i in range(0, 2400, 2)] + [f"{i:040x}" for i in range(1, 400, 2)]
    for key in keys[: len(keys) // 2]:
        store.blob_path(key).parent.mkdir(parents=True, exist_ok=True)
        store.blob_path(key).write_bytes(b"x")
    store.blob_path(keys[0]).with_suffix(".jpg").write_bytes(b"x")  # another kind of blob: not a png
    listed = store.existing_blobs(keys)
    monkeypatch.setattr(store_module, "LISTING_ADVANTAGE", 0)  # every key checked on its own
    assert listed == store.existing_blobs(keys) == {k for k in keys if store.blob_path(k).exists()}
    assert len(listed) == len(keys) // 2
    assert store.existing_blobs(keys, ext="jpg") == {keys[0]}


def test_remembered_keys_follow_the_segments(tmp_path: Path) -> None:
    store = Store(tmp_path)
    store.append("renders", [render_row("aa" * 20)])
    assert store.keys("renders") == {"aa" * 20}
    store.keys("renders").add("zz")  # a copy: the caller may change it
    store.append("renders", [render_row("bb" * 20)])
    assert store.keys("renders") == {"aa" * 20, "bb" * 20}
    store.drop_rows("renders", {"aa" * 20})
    assert store.keys("renders") == {"bb" * 20}
    assert Store(tmp_path).keys("renders") == {"bb" * 20}


def test_the_memo_vouches_for_a_blob_whose_rows_recorded_several_digests(tmp_path: Path, monkeypatch) -> None:
    store = Store(tmp_path)
    key = "cc" * 20
    store.append("renders", [render_row(key)])  # an old row: no digest
    data = encode_png(np.full((4, 4, 3), 0.5, np.float32))
    atomic_write(store.blob_path(key), data)
    store.append("renders", [render_row(key, 1, "0" * 64), render_row(key, 2, sha256_bytes(data))])
    time.sleep(0.05)  # the blob's change time is a clock tick behind what follows
    hashed = HashCounter(monkeypatch)
    assert damaged_blobs(store, "renders", {key}) == set() and hashed.calls == 1
    assert damaged_blobs(store, "renders", {key}) == set() and hashed.calls == 1  # its third row's digest
    store.drop_rows("renders", {key})
    store.append("renders", [render_row(key, 3, "1" * 64)])  # no row records its digest any more
    assert damaged_blobs(store, "renders", {key}) == {key} and hashed.calls == 2


def test_a_missing_or_unremembered_blob_among_many_is_told_apart(tmp_path: Path, monkeypatch) -> None:
    store = Store(tmp_path)
    keys = [f"{i:02x}" * 20 for i in range(5)]
    for i, key in enumerate(keys):
        add_render(store, key, i)
    time.sleep(0.05)
    assert damaged_blobs(store, "renders", keys) == set()
    store.blob_path(keys[0]).unlink()
    atomic_write(store.blob_path(keys[1]), b"not a png")  # a new file: hashed again, found damaged
    hashed = HashCounter(monkeypatch)
    assert damaged_blobs(store, "renders", keys) == {keys[1]} and hashed.calls == 1
