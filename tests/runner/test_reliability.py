"""Damage and concurrency: corrupt or truncated blobs and segments, full disks, compaction under
readers, ``sweep3d cache`` (verify, repair, gc, compact, stats), and two runs on one store."""

from __future__ import annotations

import errno
import logging
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from sweep3d.cache.blobs import damaged_blobs, memo_path, sha256_bytes
from sweep3d.cache.maintenance import (
    collect_garbage,
    compact_table,
    remove_killed_writers_temp_files,
    repair,
    store_stats,
    verify,
)
from sweep3d.cache.store import Store, StoreWriteError, atomic_write
from sweep3d.cli import app
from sweep3d.core.errors import UserError
from sweep3d.results import connect as connect_results
from sweep3d.runner.pipeline import run
from tests.helpers import REPO, T0, TINY_SPEC, HashCounter, add_render, load_spec, render_row, write_spec


def flip_bytes(path: Path, at: float = 0.5, n: int = 4) -> None:
    data = bytearray(path.read_bytes())
    i = int(len(data) * at)
    for j in range(i, min(i + n, len(data))):
        data[j] ^= 0xFF
    path.write_bytes(bytes(data))


def tree(root: Path) -> dict[str, str]:
    """Every file under ``root`` (relative path) with its content digest."""
    return {str(p.relative_to(root)): sha256_bytes(p.read_bytes()) for p in sorted(root.rglob("*")) if p.is_file()}


# -- unreadable segments ---------------------------------------------------------------------


@pytest.mark.parametrize("damage", ["flipped", "truncated", "garbage", "empty"])
def test_an_unreadable_segment_is_quarantined_with_one_warning_and_skipped(tmp_path, caplog, damage):
    """By the writer lock's holder (a reader only skips it: tests/cache/test_store_audit.py)."""
    store = Store(tmp_path / "store")
    good = store.append("renders", [render_row("a"), render_row("b")])
    bad = store.append("renders", [render_row(f"k{i}", i) for i in range(200)])
    if damage == "flipped":
        flip_bytes(bad, 0.3)  # inside a data page: caught by its checksum
    elif damage == "truncated":
        bad.write_bytes(bad.read_bytes()[: bad.stat().st_size // 2])
    elif damage == "garbage":
        bad.write_bytes(os.urandom(4000))
    else:
        bad.write_bytes(b"")

    with caplog.at_level(logging.WARNING, logger="sweep3d.store"), store.lock():
        assert store.keys("renders") == {"a", "b"}
        con = store.connect()
        assert con.execute("select count(*) from renders").fetchone()[0] == 2
        assert store.keys("renders") == {"a", "b"}
    warnings = [r.getMessage() for r in caplog.records]
    assert len(warnings) == 1, warnings
    assert bad.name in warnings[0] and "quarantine" in warnings[0] and "\n" not in warnings[0]
    assert store.segments("renders") == [good]
    assert (tmp_path / "store" / "quarantine" / "tables" / "renders" / bad.name).is_file()


def test_a_reader_that_must_not_write_skips_without_moving(tmp_path, caplog):
    store = Store(tmp_path / "store")
    store.append("renders", [render_row("a")])
    bad = store.append("renders", [render_row("b")])
    bad.write_bytes(b"PAR1 not really")
    before = tree(tmp_path / "store")
    assert Store(tmp_path / "store", quarantine=False).keys("renders") == {"a"}
    assert tree(tmp_path / "store") == before


def test_drop_rows_rewrites_only_the_segments_holding_them(tmp_path):
    store = Store(tmp_path / "store")
    first = store.append("renders", [render_row("a"), render_row("b")])
    second = store.append("renders", [render_row("c")])
    untouched = store.append("renders", [render_row("d")])
    stamp = untouched.stat().st_mtime_ns
    assert store.drop_rows("renders", {"b", "c", "zz"}) == 2
    assert store.keys("renders") == {"a", "d"}
    assert first.exists() and not second.exists()  # emptied segments are removed
    assert untouched.stat().st_mtime_ns == stamp
    assert not list((tmp_path / "store").rglob("*.tmp"))


# -- full disk -------------------------------------------------------------------------------


def _enospc(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_while_writing_a_segment_is_one_line_and_leaves_no_temp_file(tmp_path, monkeypatch):
    store = Store(tmp_path / "store")
    store.append("renders", [render_row("a")])
    before = tree(tmp_path / "store")

    def half_then_full(table, where, **kwargs):
        Path(where).write_bytes(b"PAR1 half")
        _enospc()

    monkeypatch.setattr(pq, "write_table", half_then_full)
    with pytest.raises(StoreWriteError) as caught:
        store.append("renders", [render_row("b")])
    message = str(caught.value)
    assert isinstance(caught.value, UserError) and "\n" not in message
    assert "No space left on device" in message and "free some disk space" in message
    assert "experiment.store" in message
    assert tree(tmp_path / "store") == before


def test_a_full_disk_while_writing_a_blob_leaves_no_temp_file(tmp_path, monkeypatch):
    monkeypatch.setattr(os, "fsync", _enospc)
    target = tmp_path / "blobs" / "ab" / "abcd.png"
    with pytest.raises(StoreWriteError, match="No space left"):
        atomic_write(target, b"x" * 1000)
    assert [p.name for p in tmp_path.rglob("*") if p.is_file()] == []


# -- blobs a run counts as cached ------------------------------------------------------------




def test_a_run_hashes_a_blob_again_only_when_its_file_changed(tmp_path, monkeypatch):
    store = Store(tmp_path / "store")
    keys = {f"{i:02x}" * 20 for i in range(6)}
    for i, key in enumerate(sorted(keys)):
        add_render(store, key, i)
    time.sleep(0.05)  # the blobs' change time is a clock tick or more behind what follows
    hashed = HashCounter(monkeypatch)
    assert damaged_blobs(store, "renders", keys) == set() and hashed.calls == 6
    assert damaged_blobs(store, "renders", keys) == set() and hashed.calls == 6  # remembered: nothing hashed

    flipped, rewritten = sorted(keys)[:2]
    stat = store.blob_path(flipped).stat()
    flip_bytes(store.blob_path(flipped), n=8)  # in place: same size, same inode
    os.utime(store.blob_path(flipped), ns=(stat.st_atime_ns, stat.st_mtime_ns))  # and the mtime put back
    atomic_write(store.blob_path(rewritten), store.blob_path(rewritten).read_bytes())  # same bytes, new file
    assert damaged_blobs(store, "renders", keys) == {flipped}
    assert hashed.calls == 8  # only the two changed files
    assert damaged_blobs(store, "renders", keys) == {flipped} and hashed.calls == 9  # not remembered as good


def test_blob_states_taken_ahead_by_a_child_are_the_states_and_damage_is_still_found(tmp_path, monkeypatch):
    from sweep3d.cache import blobs, snapshot

    monkeypatch.setattr(snapshot, "MIN_BLOBS", 0)
    store = Store(tmp_path / "store")
    keys = [f"{i:02x}" * 20 for i in range(6)]
    for i, key in enumerate(keys):
        add_render(store, key, i)
    (store.root / "blobs" / keys[0][:2] / "leftover.png.tmp").write_bytes(b"")  # not a blob
    time.sleep(0.05)
    assert damaged_blobs(store, "renders", set(keys)) == set()  # the memo of verified blobs
    with store.lock():
        store.snapshot_states()
        assert store.state_snapshot is not None
        flipped = keys[1]
        stat = store.blob_path(flipped).stat()
        flip_bytes(store.blob_path(flipped), n=8)  # in place, mtime put back: only the change time tells
        os.utime(store.blob_path(flipped), ns=(stat.st_atime_ns, stat.st_mtime_ns))
        store.forget_states()
        store.snapshot_states()  # taken after the damage, as a run takes it before anything else
        later = "ff" * 20
        add_render(store, later)  # written after the snapshot: stat'ed directly
        asked = [*keys, later, "ee" * 20]  # and one that is not there
        assert (blobs.file_states(store, asked) == blobs._stat_states(store, asked)).all()
        assert damaged_blobs(store, "renders", set(keys)) == {flipped}
    assert store.state_snapshot is None, "a snapshot does not outlive the lock it was taken under"

    with store.lock():  # a child that fails: the states are taken in-process, nothing is lost
        monkeypatch.setattr(snapshot.stat_blobs, "__file__", str(tmp_path / "absent.py"))
        store.snapshot_states()
        assert store.state_snapshot.states(pa.array(keys)) is None
        assert (blobs.file_states(store, keys) == blobs._stat_states(store, keys)).all()


def test_a_run_forgets_its_snapshot_of_blob_states_before_it_computes(tiny_copy, monkeypatch) -> None:
    from sweep3d.cache import snapshot
    from sweep3d.driver import loop as driver
    from sweep3d.runner import pipeline

    monkeypatch.setattr(snapshot, "MIN_BLOBS", 0)
    monkeypatch.setattr(pipeline, "SNAPSHOT_MIN_JOBS", 0)  # the threshold as the pipeline reads it
    taken: list[bool] = []
    real_begin = driver.begin

    def begin(stage, plan, store, coming, found=None):
        taken.append(store.state_snapshot is not None)
        return real_begin(stage, plan, store, coming, found)

    monkeypatch.setattr(driver, "begin", begin)
    computing: list[bool] = []
    real_run = driver._Pass.run

    def compute(self):
        computing.append(self.store.state_snapshot is not None)
        return real_run(self)

    monkeypatch.setattr(driver._Pass, "run", compute)
    looked: list[str] = []
    real_look = driver.rows_and_cached
    monkeypatch.setattr(driver, "rows_and_cached", lambda stage, *a: looked.append(stage.table) or real_look(stage, *a))
    (tiny_copy / "spec.toml").write_text((tiny_copy / "spec.toml").read_text().replace("yaw = [0, 45]", "yaw = [0, 90]"))
    result = run(load_spec(tiny_copy / "spec.toml"))
    assert result.failed == 0 and [o.computed for o in result.outcomes] == [2, 2, 4]
    assert taken[:3] == [True, True, True], "every stage's first look at the store reads the snapshot"
    assert computing[:1] == [False], "gone before anything is computed and written"
    assert looked[:2] == ["images", "predictions"], "the renders found before the pass are not looked up again"
    assert taken[3:] == [True] * 3 and computing[1:] == [False] and looked[2:] == ["renders", "images", "predictions"], \
        "then the run looks again, as its next run would (runner.settled), from a snapshot taken after its writes"
    monkeypatch.setattr(pipeline, "SNAPSHOT_MIN_JOBS", 10**9)
    taken.clear()
    assert run(load_spec(tiny_copy / "spec.toml")).failed == 0
    assert taken == [False, False, False], "a plan of few jobs does not wait for the child's look at every blob"


def test_the_memo_forgets_dropped_keys_and_survives_its_own_damage(tmp_path, monkeypatch):
    store = Store(tmp_path / "store")
    keys = {"aa" * 20, "bb" * 20}
    for key in keys:
        add_render(store, key)
    assert damaged_blobs(store, "renders", keys) == set()
    store.drop_rows("renders", {"aa" * 20})
    assert damaged_blobs(store, "renders", {"bb" * 20}) == set()
    assert pq.read_table(memo_path(store, "renders")).column("key").to_pylist() == ["bb" * 20]

    memo_path(store, "renders").write_bytes(b"not parquet")
    hashed = HashCounter(monkeypatch)
    assert damaged_blobs(store, "renders", {"bb" * 20}) == set() and hashed.calls == 1  # hashed again, no error
    assert pq.read_table(memo_path(store, "renders")).num_rows == 1


def test_a_damaged_blob_without_a_recorded_digest_is_found_by_decoding(tmp_path):
    store = Store(tmp_path / "store")
    store.append("renders", [render_row("aa" * 20), render_row("bb" * 20)])  # old rows: no digest
    add_render(store, "cc" * 20)
    atomic_write(store.blob_path("aa" * 20), add_render(Store(tmp_path / "other"), "aa" * 20))  # a good PNG
    atomic_write(store.blob_path("bb" * 20), b"\x89PNG\r\n\x1a\n not really")
    assert damaged_blobs(store, "renders", {"aa" * 20, "bb" * 20, "cc" * 20, "dd" * 20}) == {"bb" * 20}


# -- verify, repair, gc, compact, stats --------------------------------------------------------


def test_verify_finds_every_kind_of_damage_and_repair_fixes_it(tmp_path):
    root = tmp_path / "store"
    store = Store(root)
    for i, key in enumerate(["aa01", "bb02", "cc03", "dd04"]):
        add_render(store, key, i)
    store.append("renders", [render_row("ee05", 9)])  # an old-style row without a digest
    atomic_write(store.blob_path("ee05"), b"\x89PNG\r\n\x1a\n not really")
    predictions = store.append("predictions", [{"pred_key": "p", "created_at": T0}])
    store.write_table_file(store.jobs_path("exp"), pq.read_table(predictions))
    assert verify(root).ok is False  # ee05 does not decode

    flip_bytes(store.blob_path("bb02"), 0.6)  # a bit flip: still a file, wrong content
    store.blob_path("cc03").unlink()  # gone
    predictions.write_bytes(predictions.read_bytes()[:40])  # truncated segment
    store.jobs_path("exp").write_bytes(b"nonsense")
    report = verify(root)
    kinds = sorted((p.kind, p.key or p.path.name) for p in report.problems)
    assert kinds == [("corrupt blob", "bb02"), ("corrupt blob", "ee05"), ("corrupt jobs table", "exp.parquet"),
                     ("corrupt segment", predictions.name), ("missing blob", "cc03")]
    assert verify(root).problems == report.problems  # verify changes nothing

    with store.lock():
        assert repair(root, verify(root)) == 5
    assert verify(root).ok
    assert Store(root).keys("renders") == {"aa01", "dd04"}  # the others are recomputed by the next run
    quarantined = {p.name for p in (root / "quarantine").rglob("*") if p.is_file()}
    assert quarantined == {"bb02.png", "ee05.png", predictions.name, "exp.parquet"}


def test_gc_removes_unreferenced_blobs_and_old_temp_files_only(tmp_path):
    root = tmp_path / "store"
    store = Store(root)
    add_render(store, "aa01")
    atomic_write(store.blob_path("ff99"), b"orphan: its run was killed before the row was written")
    old_tmp = store.blob_path("aa01").with_name(".aa01.png.dead.tmp")
    old_tmp.write_bytes(b"half")
    os.utime(old_tmp, (time.time() - 7200, time.time() - 7200))
    young_tmp = store.table_dir("renders") / ".x.parquet.live.tmp"
    young_tmp.write_bytes(b"being written")
    out = collect_garbage(root, older_than=3600)
    assert (out.blobs, out.temp_files) == (1, 1)
    assert store.blob_path("aa01").exists() and not store.blob_path("ff99").exists()
    assert young_tmp.exists() and not old_tmp.exists()
    assert verify(root).ok


def test_compaction_merges_segments_drops_duplicates_and_leaves_the_views_as_they_were(tmp_path):
    root = tmp_path / "store"
    store = Store(root)
    for i in range(30):
        store.append("renders", [render_row(f"k{i:02d}", i, seconds=i), render_row(f"k{i // 2:02d}", 100 + i, seconds=-1)])
    con = store.connect()
    before = con.execute("select * from renders order by render_key").fetchall()
    assert len(before) == 30 and all(r[4] >= 0 for r in before)  # the first row of each key wins

    done = compact_table(store, "renders")
    assert (done.segments_before, done.rows_before, done.rows_after) == (30, 60, 30)
    assert len(store.segments("renders")) == 1
    assert Store(root).connect().execute("select * from renders order by render_key").fetchall() == before
    assert con.execute("select * from renders order by render_key").fetchall() == before  # an open connection too
    assert compact_table(store, "renders") is None  # nothing left to do

    on_disk = list(store.table_dir("renders").glob("*.parquet"))
    assert len(on_disk) == 31  # the replaced segments wait out their grace period for open readers
    assert store.sweep_superseded("renders") == 0
    assert store.sweep_superseded("renders", older_than=0) == 30
    assert list(store.table_dir("renders").glob("*")) == store.segments("renders")
    assert Store(root).connect().execute("select * from renders order by render_key").fetchall() == before


def test_readers_see_every_row_exactly_once_while_compaction_runs(tmp_path):
    """A reader thread reads through fresh Store objects (keys, and DuckDB views) while the table
    gets later duplicate rows and is compacted over and over: every reading shows each key once,
    and always the same (first) row of it — no gap, no duplicate, no flip."""
    root = tmp_path / "store"
    store = Store(root)
    n = 360
    for i in range(0, n, 3):
        store.append("renders", [render_row(f"k{i + j}", 0, seconds=1.0) for j in range(3)])
    seen: list[tuple] = []
    errors: list[BaseException] = []
    stop = threading.Event()

    def reader():
        while not stop.is_set():
            try:
                reading = Store(root)
                keys = len(reading.keys("renders"))
                rows, total = reading.connect().execute("select count(*), sum(seconds) from renders").fetchone()
                seen.append((keys, rows, total))
            except BaseException as exc:  # noqa: BLE001
                errors.append(exc)

    thread = threading.Thread(target=reader)
    thread.start()
    try:
        for round_ in range(8):
            for i in range(15):  # later duplicates of existing keys: the views must keep showing the first
                store.append("renders", [render_row(f"k{(round_ * 15 + i) % n}", 10 + round_, seconds=-1.0)])
            compact_table(store, "renders")
    finally:
        stop.set()
        thread.join()
    assert not errors, errors[:3]
    assert len(seen) > 5
    assert all(s == (n, n, float(n)) for s in seen), [s for s in seen if s != (n, n, float(n))][:5]
    assert len(store.segments("renders")) == 1


def test_stats_count_files_rows_and_bytes(tmp_path):
    root = tmp_path / "store"
    store = Store(root)
    add_render(store, "aa01")
    add_render(store, "bb02", 1)
    store.append("renders", [render_row("aa01", 5)])  # a duplicate row
    stats = {s.name: s for s in store_stats(root)}
    assert (stats["renders"].files, stats["renders"].rows, stats["renders"].keys) == (3, 3, 2)
    assert stats["blobs"].files == 2 and stats["blobs"].bytes > 0
    assert stats["predictions"].files == 0


# -- a real run's store ----------------------------------------------------------------------


def _results(folder: Path) -> list[tuple]:
    con = connect_results(Store(folder / "store"), "tiny")
    return con.execute("SELECT job, pred_key, top1_label, correct, loss FROM results ORDER BY job").fetchall()


def _same_results(got: list[tuple], want: list[tuple]) -> None:
    assert len(got) == len(want)
    for a, b in zip(got, want):
        assert a[:4] == b[:4]
        assert a[4] == pytest.approx(b[4], abs=0.05)


@pytest.mark.slow
def test_damaged_blobs_and_segments_are_recomputed_not_fatal(tiny_copy: Path, caplog) -> None:
    """A flipped render blob, a truncated image blob and a truncated predictions segment: the next
    run warns, quarantines, recomputes exactly what is needed (rendering again with Blender)."""
    root = tiny_copy / "store"
    want = _results(tiny_copy)
    con = connect_results(Store(root), "tiny")
    render, image = con.execute(
        "SELECT render_key, image_key FROM jobs WHERE image_key <> render_key ORDER BY job LIMIT 1").fetchone()
    flip_bytes(Store(root).blob_path(render), 0.7)
    image_blob = Store(root).blob_path(image)
    image_blob.write_bytes(image_blob.read_bytes()[:50])
    for segment in Store(root).segments("predictions"):
        segment.write_bytes(segment.read_bytes()[:-20])

    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        result = run(load_spec(tiny_copy / "spec.toml"))
    assert result.failed == 0
    assert result.outcome("render").computed == 1  # the damaged render, found by the stages reading it
    assert result.outcome("postprocess").computed == 1
    assert result.outcome("infer").computed == 8
    assert any("quarantine" in r.getMessage() for r in caplog.records)
    _same_results(_results(tiny_copy), want)
    assert verify(root).ok
    assert Store(root).keys("renders") >= {render} and len(Store(root).keys("renders")) == 4


@pytest.mark.slow
def test_a_plain_rerun_repairs_damaged_renders_whose_results_are_cached(tiny_copy: Path, caplog) -> None:
    """The issue's reproduction: 8 bytes flipped in the middle of two render blobs of a finished
    store. The report shows them as damaged, not as pictures; the next plain run warns once,
    renders those two again and nothing else; the store then verifies clean."""
    import json

    from sweep3d.report import write_report

    spec, root = tiny_copy / "spec.toml", tiny_copy / "store"
    want = _results(tiny_copy)
    con = connect_results(Store(root), "tiny")
    damaged = [k for (k,) in con.execute(
        "SELECT DISTINCT render_key FROM jobs WHERE image_key = render_key ORDER BY 1 LIMIT 2").fetchall()]
    for key in damaged:  # each is also the image of a job: the report shows it
        flip_bytes(Store(root).blob_path(key), 0.5, n=8)

    html = write_report(load_spec(spec)).read_text(encoding="utf-8")
    problems = json.loads(re.search(r'id="thumb-problems">(.*?)</script>', html, re.S).group(1))
    assert sorted(problems.values()) == ["damaged", "damaged"] and "2 damaged" in html
    assert CliRunner().invoke(app, ["cache", "verify", str(spec)]).exit_code == 2

    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        result = run(load_spec(spec))
    warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1 and "\n" not in warnings[0], warnings
    assert "2 renders blob(s) are damaged" in warnings[0] and "recomputing" in warnings[0]
    assert {o.stage: (o.computed, o.failed) for o in result.outcomes} == {
        "render": (2, 0), "postprocess": (0, 0), "infer": (0, 0)}
    assert sorted(p.name for p in (root / "quarantine").rglob("*.png")) == sorted(f"{k}.png" for k in damaged)
    verified = CliRunner().invoke(app, ["cache", "verify", str(spec)])
    assert verified.exit_code == 0, verified.output
    assert _results(tiny_copy) == want  # the predictions were cached: exactly the same rows

    caplog.clear()
    again = run(load_spec(spec))
    assert sum(o.computed for o in again.outcomes) == 0 and not caplog.records
    html = write_report(load_spec(spec)).read_text(encoding="utf-8")
    assert "damaged" not in re.search(r'id="thumb-problems">(.*?)</script>', html, re.S).group(1)


@pytest.mark.slow
def test_cache_commands_on_a_real_store(tiny_copy: Path) -> None:
    spec = str(tiny_copy / "spec.toml")
    root = tiny_copy / "store"
    runner = CliRunner()
    want = _results(tiny_copy)

    stats = runner.invoke(app, ["cache", "stats", spec])
    assert stats.exit_code == 0, stats.output
    assert re.search(r"renders\s+│\s+\d+\s+│\s+4\s+│\s+4\s", stats.output), stats.output
    assert "predictions" in stats.output and "blobs" in stats.output and "total" in stats.output

    ok = runner.invoke(app, ["cache", "verify", spec])
    assert ok.exit_code == 0 and "store OK" in ok.output

    blob = Store(root).blob_path(sorted(Store(root).keys("images"))[0])
    flip_bytes(blob)
    found = runner.invoke(app, ["cache", "verify", spec])
    assert found.exit_code == 2
    assert "corrupt blob" in found.output and blob.name in found.output and "--repair" in found.output
    fixed = runner.invoke(app, ["cache", "verify", spec, "--repair"])
    assert fixed.exit_code == 0 and "repaired 1" in fixed.output
    assert runner.invoke(app, ["cache", "verify", spec]).exit_code == 0

    atomic_write(Store(root).blob_path("ff" * 20), b"orphan")
    swept = runner.invoke(app, ["cache", "gc", spec, "--purge-quarantine"])
    assert swept.exit_code == 0 and "removed 1 unreferenced blobs" in swept.output
    assert not (root / "quarantine").exists()

    again = run(load_spec(tiny_copy / "spec.toml"))  # recomputes the repaired image
    assert again.outcome("postprocess").computed == 1 and again.outcome("render").computed == 0
    compacted = runner.invoke(app, ["cache", "compact", spec])
    assert compacted.exit_code == 0 and "segments → 1" in compacted.output
    assert all(len(Store(root).segments(t)) <= 1 for t in ("renders", "images", "predictions", "runs"))
    after = run(load_spec(tiny_copy / "spec.toml"))
    assert {o.stage: o.computed for o in after.outcomes} == {"render": 0, "postprocess": 0, "infer": 0}
    _same_results(_results(tiny_copy), want)
    assert runner.invoke(app, ["cache", "verify", spec]).exit_code == 0


@pytest.mark.parametrize("wait", ["-5", "nan", "inf"])
@pytest.mark.parametrize("command", [["run"], ["cache", "verify"], ["cache", "gc"], ["cache", "compact"]])
def test_wait_must_be_a_finite_number_of_seconds(tmp_path, command, wait) -> None:
    spec = write_spec(tmp_path, TINY_SPEC)
    result = CliRunner().invoke(app, [*command, str(spec), "--wait", wait])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"error: --wait {wait}: ") and ">= 0" in lines[0], lines


# -- two runs at once ------------------------------------------------------------------------

CONCURRENT_SPEC = TINY_SPEC.replace("yaw = [0, 45]", "yaw = { range = [-180, 180] }").replace(
    '[policy]\ntype = "grid"', '[policy]\ntype = "grid"\nsamples_per_dim = 8')  # yaws -180, -135, ..., 135
OTHER_SPEC = TINY_SPEC.replace('name = "tiny"', 'name = "other"').replace("yaw = [0, 45]", "yaw = [0, 30, 90]")


def _cli(folder: Path, *args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "sweep3d", *args], cwd=folder, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env={**os.environ, "PYTHONPATH": str(REPO)})


@pytest.mark.slow
def test_a_second_run_on_a_busy_store_refuses_in_one_line_or_waits_with_wait(tmp_path: Path) -> None:
    write_spec(tmp_path, CONCURRENT_SPEC)
    write_spec(tmp_path, OTHER_SPEC, name="other.toml")
    first = _cli(tmp_path, "run", "spec.toml", "--no-report")
    lock = tmp_path / "store" / "lock"
    deadline = time.monotonic() + 120
    while not (lock.exists() and lock.read_text().strip() == f"sweep3d pid {first.pid}"):
        assert first.poll() is None and time.monotonic() < deadline, first.communicate()
        time.sleep(0.02)

    refused = _cli(tmp_path, "run", "other.toml", "--no-report")
    out, err = refused.communicate(timeout=120)
    assert refused.returncode == 2, out + err
    lines = [line for line in (out + err).splitlines() if line.strip()]
    assert len(lines) == 1, lines
    assert f"in use by sweep3d pid {first.pid}" in lines[0] and "--wait" in lines[0]
    assert first.poll() is None, "the refusal must come while the first run still holds the lock"

    waiting = _cli(tmp_path, "run", "other.toml", "--no-report", "--wait", "300")
    out1, err1 = first.communicate(timeout=300)
    assert first.returncode == 0, err1
    out2, err2 = waiting.communicate(timeout=300)
    assert waiting.returncode == 0, err2
    finished_first = re.search(r"run (\w+)\)", out1).group(1)

    store = Store(tmp_path / "store")
    runs = store.connect().execute("SELECT experiment, started_at, created_at FROM runs ORDER BY created_at").fetchall()
    assert [r[0] for r in runs] == ["tiny", "other"]
    assert runs[1][1] >= runs[0][2], "the waiting run started after the first had finished"
    assert finished_first
    assert re.search(r"render\s+│\s+6\s+│\s+4\s+│\s+2\s", out2), out2  # yaw 0 and 90 were rendered by the first
    for table in ("renders", "images", "predictions"):
        keys = [k for p in store.segments(table) for k in pq.read_table(p).column(0).to_pylist()]
        assert len(keys) == len(set(keys)), f"duplicate {table} rows"
    assert verify(tmp_path / "store").ok
    assert connect_results(store, "tiny").execute("SELECT count(*) FROM results").fetchone()[0] == 32
    assert connect_results(store, "other").execute("SELECT count(*) FROM results").fetchone()[0] == 12
    shutil.rmtree(tmp_path / "store")


def test_scratch_of_a_killed_run_is_removed_by_the_next_pool(tmp_path: Path) -> None:
    from sweep3d.stages.render.pool import SCRATCH_PREFIX, remove_stale_scratch

    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()  # a process that has exited: its pid names a killed run's folder
    dead = tmp_path / f"{SCRATCH_PREFIX}{gone.pid}-a1b2"
    live = tmp_path / f"{SCRATCH_PREFIX}{os.getpid()}-c3d4"
    other = tmp_path / f"{SCRATCH_PREFIX}ray-e5f6"  # not named after a pid: not ours to judge
    for folder in (dead, live, other):
        (folder / "uv").mkdir(parents=True)
        (folder / "frame.png").write_bytes(b"x")
    assert remove_stale_scratch(tmp_path) == 1
    assert not dead.exists() and live.exists() and other.exists()


def test_a_run_removes_every_temp_file_killed_writers_left_but_not_a_report_s(tmp_path: Path) -> None:
    root = tmp_path / "store"
    store = Store(root)
    add_render(store, "aa01")
    kept = tree(root)
    killed = [store.table_dir("renders") / ".0001.parquet.dead.tmp", store.blob_path("bb02").with_name(".bb02.png.dead.tmp"),
              root / "jobs" / ".tiny.parquet.dead.tmp", root / "models" / ".m.onnx.dead.tmp",
              store.table_dir("runs") / ".compacted-0001.json.dead.tmp"]
    unlocked = [store.report_path("tiny").with_name(".tiny.html.live.tmp"),  # `sweep3d report` takes no lock
                root / "cache" / "paint" / "cc" / ".cc03-front.png.live.tmp"]
    for path in killed + unlocked:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"half")  # just written: gc would keep them for an hour
    assert remove_killed_writers_temp_files(root) == len(killed)
    assert not any(p.exists() for p in killed) and all(p.exists() for p in unlocked)
    for path in unlocked:
        path.unlink()
    assert tree(root) == kept


def test_a_run_that_renders_nothing_still_removes_what_killed_runs_left(tiny_copy: Path) -> None:
    from sweep3d.stages.render.pool import SCRATCH_PREFIX, scratch_root

    root = tiny_copy / "store"
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()  # its pid names the scratch folder of a run killed with its workers
    scratch = scratch_root() / f"{SCRATCH_PREFIX}{gone.pid}-killed"
    temps = [Store(root).table_dir("renders") / ".0001.parquet.dead.tmp", root / "jobs" / ".tiny.parquet.dead.tmp"]
    try:
        (scratch / "uv").mkdir(parents=True)
        (scratch / "frame.png").write_bytes(b"x")
        for path in temps:
            path.write_bytes(b"half")
        result = run(load_spec(tiny_copy / "spec.toml"))
        assert {o.stage: o.computed for o in result.outcomes} == {"render": 0, "postprocess": 0, "infer": 0}
        assert not scratch.exists()
        assert not any(p.exists() for p in temps)
        assert verify(root).ok
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
