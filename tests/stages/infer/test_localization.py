"""The localization task: the evaluator's outcomes, class-activation-map boxes, boxes mapped back
through the model's resize and crop, prediction keys, and a real run with the built-in localizer.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.core.errors import SpecError
from sweep3d.stages.infer import Preprocess
from sweep3d.stages.infer.cam import map_box
from sweep3d.stages.infer.evaluators import EVALUATORS, Truth, box_iou
from sweep3d.stages.infer.labels import LabelMap
from sweep3d.stages.infer.outputs import Localized
from tests.helpers import TINY_SPEC, load_spec, plan_for, write_spec

NAMES = LabelMap([["cat"], ["dog"], ["cup"]])


def evaluate(logits, boxes, mask, iou=0.5):
    evaluator = EVALUATORS.get("localization")(top_k=2, iou=iou)
    outputs = Localized(np.array(logits, np.float32), np.array(boxes, np.float64))
    return evaluator.evaluate(outputs, [Truth((2,), mask) for _ in logits], NAMES)


def square_mask(x0=4, y0=4, x1=12, y1=12, side=16) -> np.ndarray:
    mask = np.zeros((side, side), bool)
    mask[y0:y1, x0:x1] = True
    return mask


def test_outcomes_split_wrong_class_wrong_box_missed_and_correct() -> None:
    mask = square_mask()
    right, wrong = [0, 0, 5], [5, 0, 0]
    rows = evaluate([right, right, wrong, right, [np.nan, 0, 0]],
                    [[4, 4, 12, 12], [10, 10, 16, 16], [4, 4, 12, 12], [np.nan] * 4, [4, 4, 12, 12]], mask)
    assert [r["outcome"] for r in rows] == ["correct", "wrong_box", "wrong_class", "missed", None]
    assert [r["correct"] for r in rows] == [True, False, False, False, None]
    assert [r["class_correct"] for r in rows[:4]] == [True, True, False, True]
    assert rows[0]["iou"] == 1.0 and rows[1]["iou"] == pytest.approx(4 / (64 + 36 - 4))
    assert rows[0]["pred_x1"] == 12.0 and rows[3]["pred_x0"] is None and rows[4]["valid"] is False
    # nothing of the object visible: no true box, so no IoU, whatever the model says
    hidden = evaluate([right], [[4, 4, 12, 12]], np.zeros((16, 16), bool))[0]
    assert hidden["outcome"] == "missed" and hidden["iou"] is None and hidden["correct"] is False
    # the threshold is the spec's
    assert evaluate([right], [[10, 10, 16, 16]], mask, iou=0.04)[0]["correct"] is True


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-50, 50, allow_nan=False), min_size=4, max_size=4),
       st.lists(st.floats(-50, 50, allow_nan=False), min_size=4, max_size=4))
def test_iou_is_symmetric_bounded_and_one_on_itself(a, b) -> None:
    a = [min(a[0], a[2]), min(a[1], a[3]), max(a[0], a[2]), max(a[1], a[3])]
    b = [min(b[0], b[2]), min(b[1], b[3]), max(b[0], b[2]), max(b[1], b[3])]
    ab, ba = box_iou(a, b)[0], box_iou(b, a)[0]
    assert np.isfinite(ab) and 0.0 <= ab <= 1.0 and ab == pytest.approx(ba)
    if (a[2] - a[0]) * (a[3] - a[1]) > 1e-6:
        assert box_iou(a, a)[0] == pytest.approx(1.0)


def test_the_cam_box_is_the_largest_region_above_a_fifth_of_the_peak() -> None:
    activation = np.zeros((20, 20))
    activation[2:4, 2:4] = 10.0  # the peak, but a small region
    activation[10:18, 5:15] = 3.0  # above 20 % of it, and larger
    activation[0, 19] = 1.0  # below
    assert map_box(activation) == (5.0, 10.0, 15.0, 18.0)
    assert np.isnan(map_box(np.zeros((4, 4)))).all() and np.isnan(map_box(np.full((4, 4), np.nan))).all()


@settings(max_examples=200, deadline=None)
@given(st.integers(224, 900), st.integers(224, 900), st.floats(0.05, 0.95), st.floats(0.05, 0.95))
def test_boxes_map_back_through_resize_and_crop(height, width, fx, fy) -> None:
    pre = Preprocess(resize=256, crop=224)
    scale = 256 / min(height, width)
    rows, cols = max(224, round(height * scale)), max(224, round(width * scale))
    top, left = (rows - 224) // 2, (cols - 224) // 2
    # an image point seen by the model at crop pixel (cx, cy) ...
    cx, cy = fx * 224, fy * 224
    x, y = (cx + left) * width / cols, (cy + top) * height / rows
    back = pre.to_image(np.array([[cx, cy, cx + 1, cy + 1]]), height, width)[0]
    assert back[0] == pytest.approx(x) and back[1] == pytest.approx(y)
    # ... and the identity when the image is the model's input already
    assert np.allclose(Preprocess(resize=224, crop=224).to_image(np.array([[3, 4, 50, 60]]), 224, 224), [[3, 4, 50, 60]])


def test_prediction_keys_follow_the_evaluators_own_settings(tmp_path: Path) -> None:
    def keys(evaluator: str) -> list[str]:
        spec = TINY_SPEC.replace("[policy]", f"[evaluator]\n{evaluator}\n\n[policy]")
        folder = tmp_path / str(abs(hash(evaluator)))
        folder.mkdir()
        return [j.pred_key for j in plan_for(load_spec(write_spec(folder, spec)), "m").jobs]

    classification = keys('kind = "classification"')
    assert keys('kind = "classification"\ntop_k = 5') == classification  # its default, written out
    loc = keys('kind = "localization"')
    assert not set(loc) & set(classification)
    assert not set(keys('kind = "localization"\niou = 0.7')) & set(loc)
    # another evaluator's setting is refused, naming the key and the valid ones, not ignored
    for kind, key in (("classification", "iou = 0.7"), ("localization", "score = 0.9")):
        with pytest.raises(SpecError, match=rf"evaluator\.{key.split()[0]}: unknown setting for evaluator "
                                            rf"'{kind}'; valid: kind, passes, min_visible, top_k"):
            keys(f'kind = "{kind}"\n{key}')


def test_the_localization_evaluator_asks_for_the_mask_pass(tmp_path: Path) -> None:
    from sweep3d.driver.passes import needed_passes

    spec = load_spec(write_spec(tmp_path, TINY_SPEC.replace("[policy]", '[evaluator]\nkind = "localization"\n\n[policy]')))
    assert needed_passes(spec) == ("mask",)
    assert all(j.truth_key for j in plan_for(spec, "m").jobs)


@pytest.mark.torch
def test_cam_logits_are_the_models_own_and_its_box_lies_in_the_input() -> None:
    import torch

    from sweep3d.stages.infer import load_model
    from sweep3d.stages.infer.cam import cam_localize

    model = load_model("efficientnet-lite0")
    rng = np.random.default_rng(0)
    images = rng.random((2, 224, 224, 3), dtype=np.float32)
    images[1, 60:160, 80:200] = [0.9, 0.1, 0.1]
    batch = model.preprocess(images)
    logits, boxes = cam_localize(model.module, batch)
    with torch.inference_mode():
        assert np.allclose(logits, model.module(batch).numpy(), atol=1e-4)
    assert boxes.shape == (2, 4) and np.isfinite(boxes).all()
    assert (boxes[:, :2] >= 0).all() and (boxes[:, 2:] <= 224).all() and (boxes[:, 2:] > boxes[:, :2]).all()


LOCALIZE_SPEC = TINY_SPEC.replace("[policy]", '[evaluator]\nkind = "localization"\n\n[policy]')


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.torch
def test_a_localization_run_records_boxes_and_splits_its_failures(tmp_path: Path) -> None:
    from sweep3d.cache.store import Store
    from sweep3d.results import connect

    spec = write_spec(tmp_path, LOCALIZE_SPEC)
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output
    con = connect(Store(tmp_path / load_spec(spec).spec.experiment.store), load_spec(spec).spec.experiment.name)
    rows = con.execute("SELECT correct, class_correct, iou, outcome, pred_x0, pred_y0, pred_x1, pred_y1, "
                       "gt_x0, gt_y0, gt_x1, gt_y1 FROM results").fetchall()
    assert rows and con.execute("SELECT count(*) FROM truths").fetchone()[0] > 0  # the mask pass was rendered
    side = load_spec(spec).spec.render.resolution
    for correct, cls, iou, outcome, x0, y0, x1, y1, *true_box in rows:
        assert correct == bool(cls and iou is not None and iou >= 0.5)
        assert outcome == ("correct" if correct else "wrong_class" if not cls else
                           "missed" if iou is None else "wrong_box")
        if x0 is not None:
            assert 0 <= x0 < x1 <= side and 0 <= y0 < y1 <= side
        if x0 is not None and true_box[0] is not None:  # the IoU is the recorded boxes' own
            assert iou == pytest.approx(box_iou([x0, y0, x1, y1], true_box)[0])


def test_plan_counts_the_passes_in_its_estimate_and_says_so(tmp_path: Path) -> None:
    from sweep3d.spec.models import RenderSpec
    from sweep3d.stages.render.estimate import estimate_render_seconds

    render = RenderSpec()
    plain, passes, hidden = (estimate_render_seconds(render, 224, *flags) for flags in
                             ((False, False), (True, False), (True, True)))
    assert plain < passes < hidden
    spec = write_spec(tmp_path, LOCALIZE_SPEC)
    result = CliRunner().invoke(app, ["plan", str(spec)])
    assert result.exit_code == 0 and "mask passes" in " ".join(result.output.split()), result.output


def test_an_evaluator_asking_for_an_unknown_task_is_refused_in_one_line() -> None:
    from sweep3d.core.errors import UserError
    from sweep3d.stages.infer import Classifier
    from sweep3d.stages.infer.task_calls import check_task

    with pytest.raises(UserError) as caught:
        check_task(Classifier(module=None), "depth", "mine")
    assert "'depth'" in str(caught.value) and "raw" in str(caught.value) and "\n" not in str(caught.value)
