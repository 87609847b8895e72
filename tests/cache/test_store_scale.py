"""What makes a rerun of a million cached jobs cheap keeps the store's answers: blobs found by a
listing are the blobs a check per key finds, remembered keys follow the segments, and the blob
memo compared as columns vouches for exactly what it vouched for before."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import sweep3d.cache.store_blobs as store_module  # the blobs and their listings
from sweep3d.cache.blobs import damaged_blobs, sha256_bytes
from sweep3d.cache.store import Store, atomic_write
from sweep3d.core.pixels import encode_png
from tests.helpers import HashCounter, add_render, examples, render_row


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


def _verified_renders(root: Path, n: int) -> tuple[Store, list[str]]:
    """A store of ``n`` renders whose blobs a first check verified (the memo holds them all)."""
    store = Store(root)
    keys = [f"{i:02x}" * 20 for i in range(n)]
    for i, key in enumerate(keys):
        add_render(store, key, i)
    time.sleep(0.05)  # the blobs' change time is a clock tick behind what follows
    assert damaged_blobs(store, "renders", keys) == set()
    return store, keys


def test_a_missing_or_unremembered_blob_among_many_is_told_apart(tmp_path: Path, monkeypatch) -> None:
    store, keys = _verified_renders(tmp_path, 5)
    store.blob_path(keys[0]).unlink()
    atomic_write(store.blob_path(keys[1]), b"not a png")  # a new file: hashed again, found damaged
    hashed = HashCounter(monkeypatch)
    assert damaged_blobs(store, "renders", keys) == {keys[1]} and hashed.calls == 1


def test_the_memo_keeps_other_plans_blobs_and_forgets_those_whose_rows_are_gone(tmp_path: Path, monkeypatch) -> None:
    from sweep3d.cache.blobs import memo_path
    from sweep3d.cache.store import read_parquet

    store, keys = _verified_renders(tmp_path, 5)
    hashed = HashCounter(monkeypatch)
    assert damaged_blobs(store, "renders", keys[:3]) == set() and hashed.calls == 0  # a plan with fewer jobs
    assert sorted(read_parquet(memo_path(store, "renders")).column("key").to_pylist()) == keys
    store.drop_rows("renders", {keys[4]})
    assert damaged_blobs(store, "renders", keys[:3]) == set() and hashed.calls == 0
    assert sorted(read_parquet(memo_path(store, "renders")).column("key").to_pylist()) == keys[:4]


class _Clock:
    """The store's ``time`` module, with its clock ``ahead`` seconds ahead: every folder then
    changed long before a listing is taken (``os.utime`` cannot date a change back, it moves the
    change time on)."""

    def __init__(self, monkeypatch) -> None:
        self.ahead = 0.0
        monkeypatch.setattr(store_module, "time", self)

    def __getattr__(self, name: str):
        return getattr(time, name)

    def time_ns(self) -> int:
        return time.time_ns() + int(self.ahead * 1e9)


def _count_listings(monkeypatch) -> list[int]:
    calls = [0]
    real = os.listdir

    def counted(path):
        calls[0] += 1
        return real(path)

    monkeypatch.setattr(store_module.os, "listdir", counted)
    return calls


def test_a_blob_folder_is_listed_once_while_it_stays_the_same(tmp_path: Path, monkeypatch) -> None:
    store = Store(tmp_path)
    keys = [f"aa{i:038x}" for i in range(1200)]
    for key in keys[:1000]:
        store.blob_path(key).parent.mkdir(parents=True, exist_ok=True)
        store.blob_path(key).write_bytes(b"x")
    folder = store.blob_path(keys[0]).parent
    clock, listings = _Clock(monkeypatch), _count_listings(monkeypatch)
    assert store.existing_blobs(keys) == set(keys[:1000]) and listings[0] == 1
    assert store.existing_blobs(keys) == set(keys[:1000]) and listings[0] == 2  # it just changed: listed again
    clock.ahead = 60.0
    assert store.existing_blobs(keys) == set(keys[:1000]) and listings[0] == 3
    assert store.existing_blobs(keys) == set(keys[:1000]) and listings[0] == 3  # settled: remembered
    assert Store(tmp_path).existing_blobs(keys) == set(keys[:1000]) and listings[0] == 4  # per store object
    store.blob_path(keys[1000]).write_bytes(b"x")  # a new blob moves the folder's times on
    assert store.existing_blobs(keys) == set(keys[:1001]) and listings[0] == 5
    store.quarantine(store.blob_path(keys[0]))  # so does one moved away
    assert store.existing_blobs(keys) == set(keys[1:1001]) and listings[0] == 6
    remembered_mtime = folder.stat().st_mtime_ns
    (folder / f"{keys[1]}.png").unlink()
    os.utime(folder, ns=(folder.stat().st_atime_ns, remembered_mtime))  # mtime set back: the change time moved
    assert store.existing_blobs(keys) == set(keys[2:1001]) and listings[0] == 7


def test_a_run_sweeps_temp_files_and_checks_blobs_from_one_listing(tmp_path: Path, monkeypatch) -> None:
    from sweep3d.cache.maintenance import remove_killed_writers_temp_files

    store = Store(tmp_path)
    keys = [f"{f}{i:038x}" for f in ("ab", "cd") for i in range(800)]
    for key in keys:
        store.blob_path(key).parent.mkdir(parents=True, exist_ok=True)
        store.blob_path(key).write_bytes(b"x")
    temp = store.blob_path(keys[0]).with_name(f".{keys[0]}.png.dead.tmp")
    stray = store.blob_path(keys[0]).parent / "stray" / ".deep.tmp"  # rglob found these too
    stray.parent.mkdir()
    for path in (temp, stray):
        path.write_bytes(b"half")
    clock, listings = _Clock(monkeypatch), _count_listings(monkeypatch)
    clock.ahead = 60.0
    assert remove_killed_writers_temp_files(tmp_path, store) == 2
    assert not temp.exists() and not stray.exists() and listings[0] == 2
    assert store.existing_blobs(keys) == set(keys)
    assert listings[0] == 3  # "ab" changed (its temp file went): listed again; "cd" was not


def test_a_run_over_many_blobs_reads_the_blob_folders_from_its_snapshot_alone(tmp_path: Path, monkeypatch) -> None:
    from sweep3d.cache import snapshot
    from sweep3d.cache.maintenance import remove_killed_writers_temp_files

    monkeypatch.setattr(snapshot, "MIN_BLOBS", 0)
    store = Store(tmp_path)
    keys = [f"{f}{i:038x}" for f in ("ab", "cd") for i in range(800)]
    for key in keys:
        store.blob_path(key).parent.mkdir(parents=True, exist_ok=True)
        store.blob_path(key).write_bytes(b"x")
    folder = store.blob_path(keys[0]).parent
    temp, stray = folder / f".{keys[0]}.png.dead.tmp", folder / "stray" / ".deep.tmp"
    stray.parent.mkdir()
    for path in (temp, stray, folder / f"{keys[1]}.depth.npz", folder / "cd0123.png"):  # not blobs of "ab"
        path.write_bytes(b"half")
    listed = {name: sorted(Store(tmp_path).blob_listing(name).others) for name in ("ab", "cd")}
    with store.lock():
        store.snapshot_states()
        listings = _count_listings(monkeypatch)
        assert {name: sorted(store.blob_others(name)) for name in ("ab", "cd")} == listed
        assert store.existing_blobs([*keys, "ab" + "f" * 38]) == set(keys)
        assert remove_killed_writers_temp_files(tmp_path, store) == 2
        assert listings[0] == 0, "the parent lists no blob folder the child listed"
    assert not temp.exists() and not stray.exists()
    assert store.existing_blobs(keys) == set(keys)  # the snapshot gone with the lock: listed as before


def test_a_table_file_written_again_with_the_same_rows_keeps_its_state(tmp_path: Path) -> None:
    import pyarrow as pa

    store = Store(tmp_path)
    path = store.jobs_path("e")
    table = pa.table({"job": list(range(1000)), "pred_key": [f"k{i}" for i in range(1000)]})
    assert store.write_table_file(path, table, keep_same=True)
    before = path.stat()
    assert not store.write_table_file(path, table, keep_same=True)
    assert (path.stat().st_ino, path.stat().st_mtime_ns) == (before.st_ino, before.st_mtime_ns)
    changed = table.set_column(1, "pred_key", pa.array([f"k{i + 1}" for i in range(1000)]))
    assert store.write_table_file(path, changed, keep_same=True)
    assert store.read_segment(path).equals(changed)
    flipped = bytearray(path.read_bytes())
    flipped[len(flipped) // 2] ^= 0xFF
    path.write_bytes(bytes(flipped))  # damaged: rewritten whole
    assert store.write_table_file(path, changed, keep_same=True)
    assert Store(tmp_path).read_segment(path).equals(changed)


@settings(max_examples=examples(150), deadline=None)
@given(st.lists(st.sampled_from(["ab12.png", "ab.png", "a.png", ".png", "ab1.tmp", ".ab1.png.x.tmp", "cd12.png",
                                 "ab", "abpng", "ab12.png.png"]), max_size=8),
       st.sampled_from(["ab", "a", "", "abc"]))
def test_a_listing_splits_into_keys_and_the_rest_as_a_name_by_name_check_does(names: list[str], folder: str) -> None:
    blob = [name.endswith(".png") and name[:-4][:2] == folder for name in names]  # <key>.png, the key in its folder
    expected = ([n[:-4] for n, b in zip(names, blob) if b], [n for n, b in zip(names, blob) if not b])
    assert store_module._split_listing(names, folder, ".png") == expected


def test_a_pass_blob_whose_name_ends_like_a_blob_is_found_by_a_listing(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(store_module, "LISTING_ADVANTAGE", 100)  # list the folder (as on tmpfs), not a stat per key
    store = Store(tmp_path)
    keys = [f"ab{i:038x}" for i in range(1200)]
    for key in keys:
        store.blob_path(key, "mask.png").parent.mkdir(parents=True, exist_ok=True)
        store.blob_path(key, "mask.png").write_bytes(b"x")
        store.blob_path(key, "depth.npz").write_bytes(b"x")
    assert store.existing_blobs(keys, "mask.png") == set(keys)
    assert store.existing_blobs(keys, "depth.npz") == set(keys)
    assert store.existing_blobs(keys) == set()  # no RGB blob among them
