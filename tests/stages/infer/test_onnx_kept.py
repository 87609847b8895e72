"""ONNX exports and their checks kept in the store and the user's cache folder (``onnx_kept``),
and ONNX Runtime answering without torch where both are kept."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from sweep3d.core.pixels import from_uint8
from sweep3d.stages.infer import Preprocess, onnx_kept, predict
from sweep3d.stages.infer.onnx_backend import OnnxRunner
from tests.helpers.models import tied_model

pytestmark = pytest.mark.torch


@pytest.fixture
def user_cache(tmp_path, monkeypatch):
    folder = tmp_path / "user"
    monkeypatch.setenv(onnx_kept.CACHE_VARIABLE, str(folder))
    return folder


def _never(*_args):
    raise AssertionError("torch was asked for")


def test_a_fresh_store_takes_the_export_and_its_check_and_never_loads_torch(tmp_path, user_cache, monkeypatch) -> None:
    model = tied_model()
    first = OnnxRunner(model, tmp_path / "a", "tied", threads=1)
    assert (tmp_path / "a" / "tied.onnx").is_file() and (user_cache / "onnx" / "tied.onnx").is_file()
    checks = sorted((user_cache / "onnx").glob("tied.check-*.json"))
    assert len(checks) == 1 and json.loads(checks[0].read_text())["error"] == first.error
    monkeypatch.setattr(OnnxRunner, "_export", _never)
    monkeypatch.setattr(OnnxRunner, "_check", _never)
    fresh = OnnxRunner(_never, tmp_path / "b", "tied", threads=1)  # its loader must not run either
    assert fresh.error == first.error and (tmp_path / "b" / "tied.onnx").read_bytes() == (tmp_path / "a" / "tied.onnx").read_bytes()
    assert sorted(p.name for p in (tmp_path / "b").glob("tied.check-*.json")) == [checks[0].name]  # kept in the store too
    images = np.random.default_rng(0).random((3, 32, 32, 3), dtype=np.float32)
    batch = model.preprocess(images).numpy()
    assert np.array_equal(fresh(batch), first(batch))


def test_another_graph_or_release_is_checked_again(tmp_path, user_cache, monkeypatch) -> None:
    runner = OnnxRunner(tied_model(), tmp_path, "tied", threads=1)
    name = onnx_kept.check_name(runner.path, ["CPUExecutionProvider"])
    assert onnx_kept.checked_error(runner.path, ["CPUExecutionProvider"]) == runner.error
    assert onnx_kept.check_name(runner.path, ["CUDAExecutionProvider", "CPUExecutionProvider"]) != name
    monkeypatch.setattr(onnx_kept, "_versions", lambda: {"torch": "99", "onnxruntime": "1", "numpy": "1"})
    assert onnx_kept.checked_error(runner.path, ["CPUExecutionProvider"]) is None  # a new release: check again
    monkeypatch.undo()
    with open(runner.path, "ab") as fh:  # the graph's bytes changed: its old check says nothing of it
        fh.write(b"\0")
    assert onnx_kept.checked_error(runner.path, ["CPUExecutionProvider"]) is None


def test_a_damaged_check_file_means_a_check_not_a_guess(tmp_path, user_cache) -> None:
    runner = OnnxRunner(tied_model(), tmp_path, "tied", threads=1)
    name = onnx_kept.check_name(runner.path, ["CPUExecutionProvider"])
    for folder in (tmp_path, user_cache / "onnx"):
        (folder / name).write_text('{"error": NaN}')
    assert onnx_kept.checked_error(runner.path, ["CPUExecutionProvider"]) is None
    again = OnnxRunner(tied_model(), tmp_path, "tied", threads=1)
    assert again.error == runner.error and json.loads((tmp_path / name).read_text())["error"] == runner.error


def test_off_keeps_nothing_outside_the_store(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv(onnx_kept.CACHE_VARIABLE, "off")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    assert onnx_kept.user_folder() is None
    OnnxRunner(tied_model(), tmp_path / "store", "tied", threads=1)
    assert not (tmp_path / "home").exists()
    monkeypatch.delenv(onnx_kept.CACHE_VARIABLE)
    assert onnx_kept.user_folder() == tmp_path / "home" / ".cache" / "sweep3d" / "onnx"


def test_a_near_tie_loads_torch_then_and_gets_torch_s_answer(tmp_path, user_cache) -> None:
    model = tied_model()
    OnnxRunner(model, tmp_path / "a", "tied", threads=1, exact_ranks=1)  # exported and checked
    loads = []
    runner = OnnxRunner(lambda: loads.append(1) or model, tmp_path / "b", "tied", threads=1, exact_ranks=1)
    assert loads == []
    images = np.random.default_rng(1).random((2, 40, 40, 3), dtype=np.float32)
    logits = predict(dataclasses.replace(model, module=None), images, runner=runner)
    assert loads == [1] and runner.by_torch == 2  # the tie at the top of every image: torch answered
    assert np.allclose(logits, predict(model, images), rtol=0, atol=1e-6)


@pytest.mark.parametrize("shape", [(3, 32, 32, 3), (2, 32, 40, 3), (2, 36, 36, 3), (0, 32, 32, 3)])
def test_pixels_looked_up_are_torch_s_input_bit_for_bit(shape) -> None:
    """The 8-bit fast path gives the model the same bits, in the same memory layout, as making
    the pixels float and preprocessing them with torch (a different layout changes torch's bits)."""
    import torch

    model = tied_model()
    preprocess = Preprocess(resize=32, crop=32, mean=(0.5, 0.4, 0.3), std=(0.2, 0.25, 0.3))
    pixels = np.random.default_rng(2).integers(0, 256, shape, dtype=np.uint8)
    slow = preprocess(from_uint8(pixels))
    fast = preprocess.of_pixels(pixels)
    if min(shape[1:3]) != 32:  # a resize: torch's
        assert fast is None
        return
    assert fast is not None and np.array_equal(slow.numpy(), fast)
    if len(pixels):  # an empty tensor's strides are torch's choice, and no bits follow them
        assert torch.from_numpy(fast).stride() == slow.stride()
    with torch.inference_mode():
        assert np.array_equal(model.module(slow).numpy(), model.module(torch.from_numpy(fast)).numpy())


_PREPARE = """
import sys
from sweep3d import load
from sweep3d.cache import Store
from sweep3d.runner.pipeline import plan_spec
from sweep3d.stages.infer import InferStage, ModelHandle

spec = load(sys.argv[1]).spec
model = ModelHandle.resolve(spec)
stage = InferStage(model)
stage.prepare(plan_spec(spec, model), Store(spec.store))
print(stage.backend, "torch" in sys.modules)
"""


def test_a_built_in_model_is_tried_and_served_without_torch_once_its_export_is_kept(tmp_path) -> None:
    """``prepare`` of the default backend (ONNX Runtime standing in for torch) in a fresh store:
    it takes the export and its check from the user cache (this test run's) and imports no torch
    (at the model's input size: a resize would be torch's)."""
    import subprocess
    import sys

    from tests.helpers import REPO, TINY_SPEC, write_spec

    for name in ("first", "fresh"):
        (tmp_path / name).mkdir()
    spec = TINY_SPEC.replace("resolution = 32", 'resolution = "model"')
    assert spec != TINY_SPEC
    first = write_spec(tmp_path / "first", spec)  # exports and checks, or finds them kept
    done = subprocess.run([sys.executable, "-c", _PREPARE, str(first)], capture_output=True, text=True, cwd=REPO)
    assert done.returncode == 0, done.stderr[-2000:]
    fresh = write_spec(tmp_path / "fresh", spec)
    done = subprocess.run([sys.executable, "-c", _PREPARE, str(fresh)], capture_output=True, text=True, cwd=REPO)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["onnx-as-torch", "False"]
    assert list((tmp_path / "fresh").rglob("*.onnx"))  # the store has its own copy
