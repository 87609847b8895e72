"""The real pretrained classifier and the classification evaluator."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sweep3d.errors import UserError
from sweep3d.stages.infer import IMAGENET, ClassificationEvaluator, load_model, predict
from sweep3d.stages.infer.evaluators import log_softmax
from tests.conftest import examples


@pytest.fixture(scope="module")
def lite0():
    return load_model("efficientnet-lite0")


def test_pretrained_model_recognises_a_real_photo(lite0) -> None:
    from skimage import data

    coffee = data.coffee().astype(np.float32) / 255.0  # a cup of espresso, 400×600
    logits = predict(lite0, coffee[None])
    assert logits.shape == (1, 1000) and np.isfinite(logits).all()
    top = int(logits[0].argmax())
    assert IMAGENET.names[top] in {"espresso", "cup", "coffee mug"}
    row = ClassificationEvaluator(top_k=5).evaluate(logits, [(IMAGENET.index("espresso"),)], IMAGENET)[0]
    assert row["valid"] and row["topk_labels"][0] == IMAGENET.names[top]
    assert row["loss"] == pytest.approx(-np.log(row["label_prob"]), rel=1e-6)


def test_batched_and_single_predictions_agree(lite0) -> None:
    rng = np.random.default_rng(0)
    images = rng.random((3, 64, 80, 3), dtype=np.float32)
    batch = predict(lite0, images)
    single = np.concatenate([predict(lite0, images[i : i + 1]) for i in range(3)])
    assert np.allclose(batch, single, atol=1e-4)


def test_labels_match_names_and_synonyms() -> None:
    assert IMAGENET.index("soccer ball") == IMAGENET.index("Soccer_Ball") == 805
    assert IMAGENET.index(950) == 950
    with pytest.raises(ValueError, match="did you mean"):
        IMAGENET.index("basket ball")


@pytest.mark.torch
def test_wrong_output_shape_is_a_user_error() -> None:
    import torch

    from sweep3d.stages.infer import Classifier

    bad = Classifier(torch.nn.Identity())  # returns (N, 3, H, W), not logits
    with pytest.raises(UserError, match=r"\(batch, classes\)"):
        predict(bad, np.zeros((2, 32, 32, 3), np.float32))


finite = st.floats(allow_nan=False, allow_infinity=False, width=32)  # up to ±3.4e38


@settings(max_examples=examples(200), deadline=None)
@given(st.lists(finite, min_size=2, max_size=50), st.integers(0, 1))
def test_log_softmax_is_stable_for_huge_logits(values, label) -> None:
    logits = np.array([values], dtype=np.float32)
    logp = log_softmax(logits)
    assert np.isfinite(logp).all()
    assert np.exp(logp).sum() == pytest.approx(1.0, abs=1e-9)
    row = ClassificationEvaluator(top_k=2).evaluate(logits, [(label,)], _names(len(values)))[0]
    assert row["valid"] and np.isfinite(row["loss"]) and row["loss"] >= 0
    assert row["correct"] == (int(np.argmax(logits[0])) == label)  # ties go to the first class


def test_non_finite_logits_are_flagged_invalid_not_averaged() -> None:
    logits = np.array([[1.0, np.nan, 0.0], [1.0, 2.0, 3.0]], dtype=np.float32)
    rows = ClassificationEvaluator(top_k=2).evaluate(logits, [(0,), (2,)], _names(3))
    assert rows[0]["valid"] is False and rows[0]["correct"] is None and rows[0]["loss"] is None
    assert rows[1]["valid"] and rows[1]["correct"]


def _names(n: int):
    from sweep3d.stages.infer import LabelMap

    return LabelMap([[f"c{i}"] for i in range(n)])


def test_onnx_backend_agrees_with_torch(lite0, tmp_path) -> None:
    from skimage import data

    from sweep3d.stages.infer.onnx_backend import OnnxRunner

    runner = OnnxRunner(lite0, tmp_path, "lite0", threads=2)
    assert (tmp_path / "lite0.onnx").is_file() and (tmp_path / "lite0.checked").is_file()
    coffee = data.coffee().astype(np.float32) / 255.0
    images = np.stack([coffee, coffee[::-1], coffee[:, ::-1]])
    torch_logits = predict(lite0, images)
    onnx_logits = predict(lite0, images, runner)
    assert np.array_equal(torch_logits.argmax(1), onnx_logits.argmax(1))
    assert np.abs(torch_logits - onnx_logits).max() < 1e-3
    again = OnnxRunner(lite0, tmp_path, "lite0", threads=2)  # reuses the checked export
    assert np.allclose(again(lite0.preprocess(images)), onnx_logits, atol=1e-4)  # threads: last-bit noise
