"""A model's outputs kept per image, so a changed evaluator re-evaluates without the model."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sweep3d.cache.store import Store
from sweep3d.stages.infer.kept_outputs import MAX_BYTES, KeptOutputs, outputs_key


def test_a_batch_comes_back_only_when_every_image_is_kept_and_readable(tmp_path: Path) -> None:
    kept = KeptOutputs(Store(tmp_path / "store"), "model", "torch", "classification")
    logits = np.arange(12, dtype=np.float32).reshape(3, 4)
    kept.save(["a", "b", "c"], logits)
    assert np.array_equal(kept.load(["c", "a"]), logits[[2, 0]])  # whether or not its files are written yet
    assert kept.load(["a", "d"]) is None, "one image not kept: the model runs for the batch"
    kept.close()
    assert np.array_equal(KeptOutputs(Store(tmp_path / "store"), "model", "torch", "classification").load(["b"]),
                          logits[[1]])  # on disk
    kept._path("b").write_bytes(b"not an array")
    assert kept.load(["a", "b"]) is None, "a damaged file is a miss, not an error"
    assert kept.load([]) is None


def test_files_are_written_beside_the_model_and_a_failed_write_is_raised(tmp_path: Path, monkeypatch) -> None:
    import pytest

    from sweep3d.cache import StoreWriteError
    from sweep3d.stages.infer import kept_outputs

    kept = KeptOutputs(Store(tmp_path / "store"), "model", "torch", "classification")
    kept.save(["a"], np.ones((1, 4), np.float32))
    kept.close()
    assert kept._path("a").is_file() and not kept._unwritten

    def full(path, data, durable=True):
        raise StoreWriteError(f"cannot write {path}: the disk is full")

    monkeypatch.setattr(kept_outputs, "atomic_write", full)
    kept.save(["b"], np.ones((1, 4), np.float32))
    with pytest.raises(StoreWriteError, match="disk is full"):
        kept.close()


def test_only_small_arrays_of_the_array_tasks_are_kept(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    for task in ("detection", "segmentation", "localization"):
        other = KeptOutputs(store, "model", "torch", task)
        other.save(["a"], np.zeros((1, 4), np.float32))
        assert other.load(["a"]) is None
    raw = KeptOutputs(store, "model", "torch", "raw")
    raw.save(["big"], np.zeros((1, MAX_BYTES // 4 + 1), np.float32))  # a depth map, say
    assert raw.load(["big"]) is None
    raw.save(["small"], np.ones((1, 2, 2), np.float32))
    assert raw.load(["small"]).shape == (1, 2, 2)


def test_outputs_are_keyed_by_model_answers_task_and_image() -> None:
    base = outputs_key("m", "torch", "classification", "img")
    assert len({base, outputs_key("m2", "torch", "classification", "img"), outputs_key("m", "onnx", "classification", "img"),
                outputs_key("m", "torch", "raw", "img"), outputs_key("m", "torch", "classification", "img2")}) == 5
    assert outputs_key("m", "torch", "classification", "img") == base
