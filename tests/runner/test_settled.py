"""A run that found everything complete records it; the same run again skips its per-key passes
unless something it reads changed (``sweep3d.runner.settled``)."""

from __future__ import annotations

import logging
import os
import shutil
from pathlib import Path

import pytest

from sweep3d.cache import snapshot
from sweep3d.cache.store import Store
from sweep3d.runner import pipeline, settled
from sweep3d.runner.pipeline import run
from tests.helpers import load_spec


@pytest.fixture
def many(monkeypatch):
    """Every store counts as one of many blobs, every plan as a large one: the run takes its snapshot."""
    monkeypatch.setattr(snapshot, "MIN_BLOBS", 0)
    monkeypatch.setattr(pipeline, "SNAPSHOT_MIN_JOBS", 0)


def _print(folder: Path, jobs: str = "the plans") -> str | None:
    store = Store(folder / "store")
    store.snapshot_states()
    try:
        return settled.fingerprint(store, load_spec(folder / "spec.toml"), jobs)
    finally:
        store.forget_states()


def _blobs(folder: Path) -> list[Path]:
    return sorted((folder / "store" / "blobs").rglob("*.png"))


def _flip_in_place(path: Path) -> None:
    """Flip a byte of ``path`` and put its modification time back (its change time moves on)."""
    st = path.stat()
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))


def test_the_digest_follows_every_file_and_input_a_run_reads(tiny_copy: Path, many) -> None:
    seen = [_print(tiny_copy)]
    assert seen[0] is not None and _print(tiny_copy) == seen[0], "the same store and plans: the same digest"
    seen.append(_print(tiny_copy, "another plan"))
    first, second = _blobs(tiny_copy)[:2]
    _flip_in_place(first)
    seen.append(_print(tiny_copy))
    second.unlink()
    seen.append(_print(tiny_copy))
    segment = Store(tiny_copy / "store").segments("predictions")[0]
    shutil.copy(segment, segment.with_name("9" + segment.name))  # a new segment
    seen.append(_print(tiny_copy))
    spec = tiny_copy / "spec.toml"
    spec.write_text(spec.read_text() + "\n# another spec\n")
    seen.append(_print(tiny_copy))
    (first.parent / f"{first.stem}.depth.npz").write_bytes(b"a pass")  # another kind of blob, by its name
    seen.append(_print(tiny_copy))
    assert len(set(seen)) == len(seen), seen
    (first.parent / ".killed.png.dead.tmp").write_bytes(b"half")
    assert _print(tiny_copy) == seen[-1], "a killed writer's temp file is removed before the passes, not looked at"


def test_without_a_snapshot_there_is_no_digest(tiny_copy: Path, monkeypatch) -> None:
    monkeypatch.setattr(snapshot, "MIN_BLOBS", 10**9)
    assert _print(tiny_copy) is None
    store = Store(tiny_copy / "store")
    assert settled.recall(store, load_spec(tiny_copy / "spec.toml"), None) is None


def _outcomes(result) -> list[tuple]:
    return [(o.stage, o.total, o.cached, o.computed, o.failed, o.skipped) for o in result.outcomes]


def test_a_settled_run_again_skips_its_passes_says_the_same_and_still_sweeps(tiny_copy: Path, many,
                                                                              monkeypatch) -> None:
    spec = tiny_copy / "spec.toml"
    passes: list[int] = []
    real = pipeline._run_passes
    monkeypatch.setattr(pipeline, "_run_passes", lambda *a: passes.append(1) or real(*a))
    first = run(load_spec(spec))  # the tiny run is complete: this run looks key by key, and records it
    assert passes == [1] and sum(o.computed for o in first.outcomes) == 0
    second = run(load_spec(spec))
    assert passes == [1], "the same run over the same files: its outcomes read back"
    assert _outcomes(second) == _outcomes(first)
    temp = _blobs(tiny_copy)[0].parent / ".killed.png.dead.tmp"
    temp.write_bytes(b"half")
    third = run(load_spec(spec))
    assert not temp.exists(), "what killed writers left is removed whatever the run finds"
    assert passes == [1] and _outcomes(third) == _outcomes(first)
    (tiny_copy / "store" / "verified" / "settled" / "tiny.json").write_text("{not json")
    assert _outcomes(run(load_spec(spec))) == _outcomes(first) and passes == [1, 1], "a damaged record is none"


@pytest.mark.slow
def test_damage_after_a_settled_run_is_found_and_repaired(tiny_copy: Path, many, caplog) -> None:
    """A blob flipped in place with its mtime put back, and another deleted: the next run looks
    key by key, warns, and renders those two again; the run after it is settled again."""
    spec = tiny_copy / "spec.toml"
    run(load_spec(spec))  # records the settled state
    store = Store(tiny_copy / "store")
    renders = sorted(store.keys("renders"))
    _flip_in_place(store.blob_path(renders[0]))
    store.blob_path(renders[1]).unlink()
    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        repaired = run(load_spec(spec))
    assert repaired.outcome("render").computed == 2
    assert any("damaged" in r.getMessage() for r in caplog.records)
    looked = run(load_spec(spec))  # written since: looks once more, and records
    assert sum(o.computed for o in looked.outcomes) == 0


def test_a_run_that_computed_looks_again_so_its_first_rerun_reads_back(tiny_copy: Path, many, monkeypatch) -> None:
    spec = tiny_copy / "spec.toml"
    spec.write_text(spec.read_text().replace("yaw = [0, 45]", "yaw = [0, 90]"))
    passes: list[int] = []
    real = pipeline._run_passes
    monkeypatch.setattr(pipeline, "_run_passes", lambda *a: passes.append(1) or real(*a))
    computed = run(load_spec(spec))
    assert [o.computed for o in computed.outcomes] == [2, 2, 4] and passes == [1, 1], "its passes, then a look"
    again = run(load_spec(spec))
    assert passes == [1, 1], "the first rerun reads back what the look found"
    assert [(o.stage, o.total, o.cached, o.computed) for o in again.outcomes] == \
        [(o.stage, o.total, o.total, 0) for o in computed.outcomes]


@pytest.mark.slow
def test_a_cold_run_looks_again_at_its_end_so_its_first_rerun_reads_back(tmp_path: Path, many,
                                                                           monkeypatch) -> None:
    from tests.helpers import TINY_SPEC, write_spec

    spec = write_spec(tmp_path, TINY_SPEC)
    monkeypatch.setattr(snapshot, "MIN_BLOBS", 1)  # none at its start: the snapshot is taken at its end only
    passes: list[int] = []
    real = pipeline._run_passes
    monkeypatch.setattr(pipeline, "_run_passes", lambda *a: passes.append(1) or real(*a))
    cold = run(load_spec(spec))
    assert cold.failed == 0 and sum(o.computed for o in cold.outcomes) > 0 and passes == [1, 1]
    assert _outcomes(run(load_spec(spec))) == [(o.stage, o.total, o.total, 0, 0, 0) for o in cold.outcomes]
    assert passes == [1, 1]
