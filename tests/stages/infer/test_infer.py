"""The real pretrained classifier and the classification evaluator."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sweep3d.core.errors import UserError
from sweep3d.stages.infer import IMAGENET, ClassificationEvaluator, load_model, predict
from sweep3d.stages.infer.evaluators import Truth, log_softmax
from sweep3d.stages.infer.prediction_keys import STAND_IN
from tests.helpers import TINY_SPEC, examples, write_spec
from tests.helpers.models import tied_model


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
    row = ClassificationEvaluator(top_k=5).evaluate(logits, [Truth((IMAGENET.index("espresso"),))], IMAGENET)[0]
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
    row = ClassificationEvaluator(top_k=2).evaluate(logits, [Truth((label,))], _names(len(values)))[0]
    assert row["valid"] and np.isfinite(row["loss"]) and row["loss"] >= 0
    assert row["correct"] == (int(np.argmax(logits[0])) == label)  # ties go to the first class


def test_non_finite_logits_are_flagged_invalid_not_averaged() -> None:
    logits = np.array([[1.0, np.nan, 0.0], [1.0, 2.0, 3.0]], dtype=np.float32)
    rows = ClassificationEvaluator(top_k=2).evaluate(logits, [Truth((0,)), Truth((2,))], _names(3))
    assert rows[0]["valid"] is False and rows[0]["correct"] is None and rows[0]["loss"] is None
    assert rows[1]["valid"] and rows[1]["correct"]


def _names(n: int):
    from sweep3d.stages.infer import LabelMap

    return LabelMap([[f"c{i}"] for i in range(n)])


def test_onnx_backend_agrees_with_torch(lite0, tmp_path) -> None:
    from skimage import data

    from sweep3d.stages.infer.onnx_backend import OnnxRunner

    runner = OnnxRunner(lite0, tmp_path, "lite0", threads=2)
    assert (tmp_path / "lite0.onnx").is_file()
    coffee = data.coffee().astype(np.float32) / 255.0
    images = np.stack([coffee, coffee[::-1], coffee[:, ::-1]])
    torch_logits = predict(lite0, images)
    onnx_logits = predict(lite0, images, runner=runner)
    assert np.array_equal(torch_logits.argmax(1), onnx_logits.argmax(1))
    assert 0 < np.abs(torch_logits - onnx_logits).max() < 1e-3  # not torch's own bits: ONNX Runtime ran
    again = OnnxRunner(lite0, tmp_path, "lite0", threads=2)  # reuses the export, checked again
    assert np.allclose(again(lite0.preprocess(images)), onnx_logits, atol=1e-4)  # threads: last-bit noise


@pytest.mark.torch
def test_standing_in_for_torch_runs_near_ties_through_torch(tmp_path) -> None:
    from sweep3d.stages.infer.onnx_backend import OnnxRunner

    model = tied_model()
    images = np.random.default_rng(1).random((5, 40, 40, 3), dtype=np.float32)
    torch_logits = predict(model, images)
    own = OnnxRunner(model, tmp_path, "tied", threads=1)
    assert own.by_torch == 0 and np.abs(predict(model, images, runner=own) - torch_logits).max() < 1e-3
    stand_in = OnnxRunner(model, tmp_path, "tied", threads=1, exact_ranks=1)
    logits = predict(model, images, runner=stand_in)
    assert stand_in.by_torch == 5  # every image has the tie at the top: each went through torch
    assert np.allclose(logits, torch_logits, rtol=0, atol=1e-6)


@settings(max_examples=examples(200), deadline=None)
@given(seed=st.integers(0, 2**32 - 1), ranks=st.integers(1, 6), scale=st.sampled_from([1e-3, 1e-2, 1.0, 10.0]),
       error=st.sampled_from([1e-5, 2.7e-4, 1e-3]))
def test_rows_without_near_ties_rank_alike_under_any_error_within_the_tolerance(seed, ranks, scale, error) -> None:
    """Whatever error the check measured (from the floor to the tolerance): a row no logit of
    which is further than it from torch's, and not flagged, ranks its top classes as torch does."""
    from sweep3d.stages.infer.onnx_backend import near_ties

    rng = np.random.default_rng(seed)
    torch_logits = (rng.standard_normal((64, 8)) * scale).astype(np.float64)
    onnx_logits = torch_logits + rng.uniform(-0.99, 0.99, torch_logits.shape) * error
    flagged = set(near_ties(onnx_logits, ranks, 2 * error).tolist())
    for row in set(range(64)) - flagged:
        assert list(np.argsort(-onnx_logits[row], kind="stable")[:ranks]) == \
            list(np.argsort(-torch_logits[row], kind="stable")[:ranks])
    assert set(near_ties(np.array([[1.0, np.nan, 0.0], [3.0, 2.0, 1.0]]), 1).tolist()) == {0}


@pytest.mark.torch
def test_the_near_tie_margin_is_the_error_the_check_measured(tmp_path) -> None:
    """A sixth as many images through torch: the margin follows what ONNX Runtime's logits were
    seen to miss by (with a safety factor), not the tolerance the check accepts."""
    from sweep3d.stages.infer.onnx_backend import FLOOR, SAFETY, TOLERANCE, OnnxRunner

    runner = OnnxRunner(tied_model(), tmp_path, "tied", threads=1, exact_ranks=1)
    assert FLOOR <= runner.error < TOLERANCE
    images = np.random.default_rng(1).random((3, 40, 40, 3), dtype=np.float32)
    logits = runner._run(runner.classifier.preprocess(images))
    measured = float(np.abs(logits - predict(runner.classifier, images)).max())
    assert measured <= runner.error / SAFETY * 4 or runner.error == FLOOR  # the check saw errors of this size


@pytest.mark.parametrize(("model", "backend", "keyed"), [
    ("", STAND_IN, None),  # left out, built-in model: ONNX Runtime standing in, under the keys it always had
    ('backend = "torch"\n', "torch", "torch"),  # written out: used as written, and named in the keys
    ('backend = "onnx"\n', "onnx", "onnx"),
    ('name = "my_models:make"\n', "torch", None),  # a user's model: torch unless asked; nothing stands in
])
def test_the_backend_that_computes_is_named_in_the_keys_unless_it_is_the_models_default(tmp_path, model, backend,
                                                                                       keyed) -> None:
    from sweep3d.stages.infer import choose_backend, key_backend
    from tests.helpers import load_spec

    (tmp_path / "my_models.py").write_text("def make():\n    raise NotImplementedError\n")
    write_spec(tmp_path, TINY_SPEC.replace("[model]\n", "[model]\n" + model))
    loaded = load_spec(tmp_path / "spec.toml")
    assert choose_backend(loaded, loaded.model) == backend and key_backend(loaded, loaded.model) == keyed


def test_torch_and_onnx_runtime_standing_in_never_share_a_prediction_key(tmp_path) -> None:
    """The two give the same ranks but probabilities apart in the 6th digit: a row one computed
    was served to a run of the other under the same key (after a full disk stopped the stand-in,
    or with renders on Ray, whose actor ran torch). Now each backend has keys of its own, and the
    stand-in's are the keys a default run always had (a store's predictions stay cached)."""
    from sweep3d.stages.infer import evaluator_key
    from sweep3d.stages.infer.prediction_keys import INFER_STAGE_VERSION, pred_key
    from tests.helpers import load_spec, plan_for

    plans = {}
    for name, model in (("default", ""), ("torch", 'backend = "torch"\n'), ("onnx", 'backend = "onnx"\n')):
        (tmp_path / name).mkdir()
        write_spec(tmp_path / name, TINY_SPEC.replace("[model]\n", "[model]\n" + model))
        plans[name] = plan_for(load_spec(tmp_path / name / "spec.toml"), "m")
    images = {name: [j.image_key for j in plan.jobs] for name, plan in plans.items()}
    assert images["default"] == images["torch"] == images["onnx"] and len(images["default"]) == 8
    preds = {name: {j.pred_key for j in plan.jobs} for name, plan in plans.items()}
    assert len(preds["default"] | preds["torch"] | preds["onnx"]) == 3 * len(preds["default"])
    spec = load_spec(tmp_path / "default" / "spec.toml")
    unnamed = {"stage": "infer", "v": INFER_STAGE_VERSION, "model": "m", "evaluator": evaluator_key(spec.evaluator)}
    assert [j.pred_key for j in plans["default"].jobs] == [
        pred_key(unnamed, j.image_key, list(spec.labels[j.object])) for j in plans["default"].jobs]


def test_a_stand_in_that_cannot_serve_refuses_instead_of_keying_torch_s_rows_as_its_own(tmp_path, monkeypatch) -> None:
    """A full disk stopped the export: the run inferred with torch under the stand-in's keys."""
    import errno

    from sweep3d.cache import Store
    from sweep3d.runner.pipeline import plan_spec
    from sweep3d.stages.infer import InferStage, ModelHandle
    from tests.helpers import load_spec

    def full_disk(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(InferStage, "_onnx", full_disk)
    loaded = load_spec(write_spec(tmp_path, TINY_SPEC))
    handle = ModelHandle.resolve(loaded)
    plan, store = plan_spec(loaded, handle), Store(loaded.store)
    with pytest.raises(UserError) as caught:
        InferStage(handle).prepare(plan, store)
    assert str(caught.value) == (
        "ONNX Runtime cannot stand in for torch for efficientnet-lite0 ([Errno 28] No space left on device); fix "
        "that and run again, or set model.backend = \"torch\" to infer with torch (its predictions are keyed "
        "apart: their probabilities differ from ONNX Runtime's in the last digits)")


def test_top5_and_label_ids_whatever_top_k() -> None:
    logits = np.array([[9.0, 8.0, 7.0, 6.0, 5.0, 4.0, 3.0]])
    names = _names(7)
    third = ClassificationEvaluator(top_k=1).evaluate(logits, [Truth((2, 6))], names)[0]
    assert third["correct"] is False and third["correct_top5"] is True and third["label_ids"] == [2, 6]
    assert len(third["topk"]) == 1  # top_k still bounds the stored ranking
    sixth = ClassificationEvaluator(top_k=5).evaluate(logits, [Truth((5,))], names)[0]
    assert sixth["correct_top5"] is False and sixth["correct"] is False


def _infer_in_batches(folder, orders: list[list[int]], images: np.ndarray, model: str, threads: str = "threads = 1\n",
                      computing: tuple[str, ...] = (), resolution: str = "32") -> list[list[dict]]:
    """Each order of ``images`` through the infer stage's own batching (``compute``), each image
    under a key of its own per order (so no kept outputs are read back); the rows in that order.
    ``computing``: the stages upstream that computed in the pass (done by the time it infers)."""
    from sweep3d.cache.store import Store
    from sweep3d.core.pixels import encode_png
    from sweep3d.driver.jobs import Job
    from sweep3d.driver.loop import Feed
    from sweep3d.runner.pipeline import plan_spec
    from sweep3d.stages.infer import InferStage, ModelHandle
    from tests.helpers import load_spec

    text = TINY_SPEC.replace("batch_size = 8\n", f"batch_size = 4\n{threads}{model}")
    loaded = load_spec(write_spec(folder, text.replace("resolution = 32\n", f"resolution = {resolution}\n")))
    handle = ModelHandle.resolve(loaded)
    plan, store = plan_spec(loaded, handle), Store(loaded.store)
    stage = InferStage(handle)
    out = []
    for n, order in enumerate(orders):
        jobs = []
        for i in order:
            key = f"{n:02d}{i:02d}" + "0" * 36
            store.blob_path(key).parent.mkdir(parents=True, exist_ok=True)
            store.blob_path(key).write_bytes(encode_png(images[i]))
            jobs.append(Job(len(jobs), "box", "white", {}, key, key, f"p{key}"))
        rows = {c.key: c.row for c in stage.compute(Feed(store, {}, jobs, computing=computing), plan, store)}
        out.append([rows[job.pred_key] for job in jobs])
    return out, stage


@pytest.mark.torch
@pytest.mark.parametrize(("model", "near_ties"), [
    pytest.param('backend = "torch"\n', False, id="torch"),  # padded to batch_size
    pytest.param('backend = "onnx"\n', False, id="onnx"),  # not padded: ONNX Runtime's rows need not be
    # ONNX Runtime standing in for torch, 101 ranks checked: near ties everywhere, each run through torch
    pytest.param("[evaluator]\ntop_k = 100\n", True, id="stand-in"),
])
def test_an_image_s_outputs_are_the_same_bytes_whatever_batch_it_is_in(tmp_path, model, near_ties) -> None:
    images = np.random.default_rng(3).random((6, 32, 32, 3), dtype=np.float32)
    # image 0 alone, in a short batch at the end, in a short batch of two after a full one, first of a full one
    orders = [[0], [1, 2, 0], [2, 3, 4, 5, 1, 0], [0, 5, 4, 3]]
    runs, stage = _infer_in_batches(tmp_path, orders, images, model)
    assert (stage._runner is not None and stage._runner.by_torch > 0) == near_ties
    seen = [rows[order.index(0)] for rows, order in zip(runs, orders)]
    for field in ("topk_probs", "label_prob", "loss", "top1"):
        assert len({repr(row[field]) for row in seen}) == 1, [row[field] for row in seen]


@pytest.mark.torch
@pytest.mark.parametrize(("model", "computing", "threads"), [
    pytest.param("", ("render", "postprocess"), [1, 3], id="stand-in beside renders: widens once they are done"),
    pytest.param("", ("postprocess",), [3], id="stand-in without renders: every core from the start"),
    pytest.param('backend = "onnx"\n', ("render", "postprocess"), [1], id="a model's own ONNX: stays on one"),
])
def test_inference_beside_renders_takes_every_core_once_upstream_is_done(tmp_path, monkeypatch, model, computing,
                                                                         threads) -> None:
    from sweep3d.stages.infer.onnx_backend import OnnxRunner

    calls: list[int] = []
    real = OnnxRunner.use_threads
    monkeypatch.setattr(OnnxRunner, "use_threads", lambda runner, n: calls.append(n) or real(runner, n))
    monkeypatch.setattr("os.cpu_count", lambda: 3)
    images = np.random.default_rng(4).random((6, 32, 32, 3), dtype=np.float32)
    _infer_in_batches(tmp_path, [[0, 1, 2, 3, 4, 5]], images, model, threads="", computing=computing)
    assert calls == threads


@pytest.mark.torch
def test_onnx_rows_are_the_same_bits_at_any_thread_count(lite0, tmp_path) -> None:
    """What lets the stand-in widen mid-pass (``InferStage._widens``): the rows stored do not
    depend on when the renders finished."""
    from skimage import data

    from sweep3d.stages.infer.onnx_backend import OnnxRunner

    coffee = data.coffee().astype(np.float32) / 255.0
    batch = lite0.preprocess(np.stack([coffee, coffee[::-1], coffee[:, ::-1]]))
    runner = OnnxRunner(lite0, tmp_path, "lite0", threads=1)
    one = runner(batch)
    for threads in (2, 3):
        runner.use_threads(threads)
        assert np.array_equal(runner(batch), one)


@pytest.mark.torch
def test_a_batch_run_in_chunks_gives_the_whole_batch_s_bits(lite0, tmp_path) -> None:
    """``OnnxRunner`` runs a CPU batch ``CHUNK`` images at a time (faster: the activations stay in
    the caches); the logits are the bits of one call on the whole batch, for any batch size."""
    from skimage import data

    from sweep3d.stages.infer.onnx_backend import CHUNK, OnnxRunner

    coffee = data.coffee().astype(np.float32) / 255.0
    views = [coffee, coffee[::-1], coffee[:, ::-1], coffee[::-1, ::-1], 1 - coffee, coffee ** 2, np.sqrt(coffee)]
    batch = lite0.preprocess(np.stack([views[i % len(views)][i:i + 380, i:i + 500] for i in range(2 * CHUNK + 1)]))
    runner = OnnxRunner(lite0, tmp_path, "lite0", threads=1)
    calls = []
    real = runner.session.run
    runner.session = type("Counted", (), {"run": lambda self, *a: calls.append(a[1]) or real(*a)})()
    for n in (1, CHUNK, CHUNK + 1, 2 * CHUNK + 1):
        calls.clear()
        whole = real(None, {runner.input: np.ascontiguousarray(batch[:n].numpy())})[0]
        assert np.array_equal(runner.unranked(batch[:n]), whole), n
        assert [len(next(iter(c.values()))) for c in calls] == [min(CHUNK, n - i) for i in range(0, n, CHUNK)]


@pytest.mark.torch
def test_near_ties_answered_aside_are_the_same_bytes(tmp_path, monkeypatch) -> None:
    """A large pass's near ties go to a process of their own (``torch_aside``): the rows are the
    bytes this process's torch gives, and the process ends with the stage."""
    from sweep3d.stages.infer import infer_stage
    from sweep3d.stages.render.child import live_children

    images = np.random.default_rng(5).random((5, 224, 224, 3), dtype=np.float32)  # the model's input: no resize
    ties = "[evaluator]\ntop_k = 100\n"  # 101 ranks checked: near ties everywhere
    (tmp_path / "here").mkdir()
    (tmp_path / "aside").mkdir()
    here, stage_here = _infer_in_batches(tmp_path / "here", [[0, 1, 2, 3, 4]], images, ties, resolution='"model"')
    assert stage_here._runner._aside is None and stage_here._runner.by_torch > 0
    monkeypatch.setattr(infer_stage, "ASIDE_MIN_IMAGES", 1)  # the tiny plan counts as large
    aside, stage_aside = _infer_in_batches(tmp_path / "aside", [[0, 1, 2, 3, 4]], images, ties, resolution='"model"')
    runner = stage_aside._runner
    assert runner._aside is not None and runner._aside.child.is_alive() and runner._classifier is None  # torch not here
    assert runner.by_torch == stage_here._runner.by_torch
    for field in ("topk_probs", "label_prob", "loss", "top1", "correct"):
        assert [repr(row[field]) for row in aside[0]] == [repr(row[field]) for row in here[0]]
    stage_aside.close()
    assert runner._aside is None and live_children() == []


@pytest.mark.torch
def test_the_process_aside_gives_torch_s_bits_in_either_memory_layout(lite0, tmp_path) -> None:
    from sweep3d.stages.infer.models import Preprocess
    from sweep3d.stages.infer.onnx_backend import OnnxRunner

    runner = OnnxRunner(lite0, tmp_path, "lite0", threads=1, exact_ranks=5)
    pixels = np.random.default_rng(6).integers(0, 256, (3, 224, 224, 3), dtype=np.uint8)
    last = Preprocess(resize=224, crop=224, mean=(0.485, 0.456, 0.406), std=(0.229, 0.224, 0.225)).of_pixels(pixels)
    rows = np.array([0, 2])
    for batch in (last, np.ascontiguousarray(last)):  # channels last (the 8-bit path), and plain
        expected = runner._torch(batch, rows)  # in this process
        runner._classifier = None  # as in a run that never loaded torch
        runner.answer_ties_aside("efficientnet-lite0")
        try:
            assert np.array_equal(runner._torch(batch, rows), expected)
            assert runner._aside is not None and runner._classifier is None  # the process aside answered
        finally:
            runner.close()


@pytest.mark.torch
def test_a_process_aside_that_does_not_answer_in_time_is_ended_and_this_process_answers(lite0, tmp_path,
                                                                                        monkeypatch) -> None:
    from sweep3d.stages.infer import torch_aside
    from sweep3d.stages.infer.models import Preprocess
    from sweep3d.stages.infer.onnx_backend import OnnxRunner
    from sweep3d.stages.render.child import live_children

    runner = OnnxRunner(lite0, tmp_path, "lite0", threads=1, exact_ranks=5)
    pixels = np.random.default_rng(7).integers(0, 256, (2, 224, 224, 3), dtype=np.uint8)
    batch = Preprocess(resize=224, crop=224, mean=(0.485, 0.456, 0.406), std=(0.229, 0.224, 0.225)).of_pixels(pixels)
    expected = runner._torch(batch, np.array([1]))
    runner._classifier = None
    monkeypatch.setattr(torch_aside, "ANSWER_WITHIN", 0.0)  # still importing torch: too late
    runner.answer_ties_aside("efficientnet-lite0")
    assert runner._aside is not None
    assert np.array_equal(runner._torch(batch, np.array([1])), expected)
    assert runner._aside is None and runner._classifier is not None and live_children() == []
