"""Detection and segmentation: checking a model's outputs, the per-image verdicts, and AP in SQL.

Pure numpy and an in-memory DuckDB: the AP views are checked against numbers worked out by hand
here and against a small Python implementation of COCO's AP.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import duckdb
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sweep3d.core.errors import UserError
from sweep3d.core.truth import decode_mask
from sweep3d.results import register_views
from sweep3d.stages.infer.evaluators import EVALUATORS, DetectionEvaluator, SegmentationEvaluator, Truth
from sweep3d.stages.infer.labels import LabelMap
from sweep3d.stages.infer.outputs import Detections, detections_from, segment_scores_from

LABELS = LabelMap([["cup"], ["dog"], ["cat"]])
H, W = 100, 100
TRUE_BOX = (10, 20, 50, 60)  # x0, y0, x1, y1


def object_mask() -> np.ndarray:
    mask = np.zeros((H, W), dtype=bool)
    x0, y0, x1, y1 = TRUE_BOX
    mask[y0:y1, x0:x1] = True
    return mask


def detect(boxes: list, labels: list[int], scores: list[float], mask: np.ndarray | None = None, **kw: Any) -> dict:
    found = Detections(np.asarray(boxes, dtype=np.float64).reshape(-1, 4), np.asarray(labels, dtype=np.int64),
                       np.asarray(scores, dtype=np.float64))
    truth = Truth(ids=(0,), mask=object_mask() if mask is None else mask)
    [row] = DetectionEvaluator(**kw).evaluate([found], [truth], LABELS)
    assert set(row) == set(DetectionEvaluator.schema.names)
    return row


# -- the detection evaluator ------------------------------------------------------------------
def test_registered_with_their_tasks() -> None:
    assert EVALUATORS.get("detection") is DetectionEvaluator and DetectionEvaluator.task == "detection"
    assert EVALUATORS.get("segmentation") is SegmentationEvaluator and SegmentationEvaluator.passes == ("mask",)
    assert DetectionEvaluator(iou=0.7, score=0.3).key_part() == {"iou": 0.7, "score": 0.3}
    assert SegmentationEvaluator(iou=0.6).key_part() == {"iou": 0.6}


def test_the_oracle_is_correct() -> None:
    row = detect([TRUE_BOX], [0], [1.0])
    assert row["valid"] and row["correct"] and row["outcome"] == "correct" and row["class_correct"]
    assert row["iou"] == 1.0 and row["score"] == 1.0 and row["top1_label"] == "cup"
    assert (row["pred_x0"], row["pred_y0"], row["pred_x1"], row["pred_y1"]) == TRUE_BOX
    assert row["boxes"] == 1 and row["false_positives"] == 0
    assert row["det_scores"] == [1.0] and row["det_ious"] == [1.0]


def test_the_oracle_shifted_by_60_percent_of_its_width_is_a_wrong_box() -> None:
    x0, y0, x1, y1 = TRUE_BOX
    shift = 0.6 * (x1 - x0)
    row = detect([(x0 + shift, y0, x1 + shift, y1)], [0], [0.9])
    assert row["iou"] == pytest.approx(0.4 / 1.6) and row["iou"] < 0.5
    assert not row["correct"] and row["outcome"] == "wrong_box" and row["class_correct"]
    assert row["false_positives"] == 1 and row["pred_x0"] == pytest.approx(x0 + shift)


def test_another_class_on_the_true_box_is_a_wrong_class() -> None:
    row = detect([TRUE_BOX], [1], [0.9])
    assert not row["correct"] and row["outcome"] == "wrong_class" and not row["class_correct"]
    assert row["iou"] is None and row["top1_label"] == "dog" and row["score"] == 0.9
    assert row["det_scores"] == [] and row["det_ious"] == []  # no detection of the object's class
    far = detect([(80, 80, 95, 95)], [1], [0.9])  # another class, elsewhere: nothing on the object
    assert far["outcome"] == "missed"


def test_nothing_kept_is_missed_but_still_listed_for_ap() -> None:
    row = detect([TRUE_BOX], [0], [0.3])
    assert not row["correct"] and row["outcome"] == "missed" and not row["class_correct"]
    assert row["boxes"] == 0 and row["false_positives"] == 0
    assert row["iou"] is None and row["score"] is None and row["top1_label"] is None and row["pred_x0"] is None
    assert row["det_scores"] == [pytest.approx(0.3)] and row["det_ious"] == [1.0]
    assert detect([], [], [])["outcome"] == "missed"


def test_false_positives_and_the_chosen_box() -> None:
    boxes = [(70, 70, 90, 90), TRUE_BOX, (12, 22, 50, 60), (0, 0, 5, 5)]
    row = detect(boxes, [0, 0, 0, 2], [0.95, 0.8, 0.9, 0.99])
    assert row["correct"] and row["boxes"] == 4 and row["false_positives"] == 3
    assert row["iou"] == 1.0 and row["score"] == 0.8  # the best overlap, not the best score
    assert row["det_scores"] == [pytest.approx(s) for s in (0.95, 0.9, 0.8)]  # matching ones, by score
    assert row["det_ious"][0] == 0.0 and row["det_ious"][2] == 1.0
    wrong = detect([(70, 70, 90, 90), (0, 0, 5, 5)], [2, 0], [0.7, 0.6])
    assert wrong["outcome"] == "wrong_box" and wrong["false_positives"] == 2


def test_a_hidden_object_is_missed_with_no_iou() -> None:
    row = detect([TRUE_BOX], [0], [1.0], mask=np.zeros((H, W), dtype=bool))
    assert not row["correct"] and row["outcome"] == "missed" and row["iou"] is None
    assert row["det_ious"] == [0.0]


# -- checking a detector's output --------------------------------------------------------------
def one(boxes: Any = ((0.0, 0.0, 5.0, 5.0),), labels: Any = (1,), scores: Any = (0.5,)) -> dict:
    return {"boxes": np.asarray(boxes, dtype=np.float32), "labels": np.asarray(labels), "scores": np.asarray(scores)}


@pytest.mark.torch
def test_detections_from_accepts_torchvision_output() -> None:
    import torch

    out = [{"boxes": torch.tensor([[1.0, 2.0, 3.0, 4.0]]), "labels": torch.tensor([2]),
            "scores": torch.tensor([0.7], dtype=torch.bfloat16)},
           {"boxes": torch.zeros((0, 4)), "labels": torch.zeros(0, dtype=torch.int64), "scores": torch.zeros(0)}]
    first, empty = detections_from(tuple(out), 2, 3, "detr")
    assert first.boxes.dtype == np.float64 and first.labels.dtype == np.int64 and first.scores.dtype == np.float64
    assert first.boxes.tolist() == [[1, 2, 3, 4]] and first.labels.tolist() == [2]
    assert empty.boxes.shape == (0, 4) and empty.labels.shape == (0,)


@pytest.mark.parametrize("output", [
    {"boxes": [], "labels": [], "scores": []},  # not a list
    [one()],  # one dict for two images
    [one(), "boxes"],  # not a dict
    [one(), {"boxes": np.zeros((0, 4)), "labels": np.zeros(0)}],  # no scores
    [one(), one(boxes=[[0, 0, 1]])],  # boxes (1, 3)
    [one(), one(labels=[1, 2])],  # two labels for one box
    [one(), one(scores=[[0.5]])],  # scores (1, 1)
    [one(), one(boxes=[[0, 0, np.nan, 1]])],
    [one(), one(scores=[np.inf])],
    [one(), one(labels=[3])],  # 3 classes: ids 0..2
    [one(), one(labels=[-1])],
    [one(), one(labels=[0.5])],
    [one(), one(boxes=[[5, 0, 1, 1]])],  # x1 < x0
    [one(), one(boxes=[[0, 5, 1, 1]])],  # y1 < y0
])
def test_detections_from_refuses_bad_output_in_one_line(output: Any) -> None:
    with pytest.raises(UserError) as caught:
        detections_from(output, 2, 3, "detr")
    message = str(caught.value)
    assert "\n" not in message and "'detr'" in message


# -- segmentation -----------------------------------------------------------------------------
def segment(scores: np.ndarray, mask: np.ndarray | None = None) -> dict:
    truth = Truth(ids=(0,), mask=object_mask() if mask is None else mask)
    [row] = SegmentationEvaluator().evaluate(scores[None], [truth], LABELS)
    assert set(row) == set(SegmentationEvaluator.schema.names)
    return row


def scores_for(classes: np.ndarray) -> np.ndarray:
    """Scores (3, H, W) whose argmax is ``classes`` (H, W)."""
    return np.stack([(classes == c).astype(np.float32) for c in range(3)])


def test_a_perfect_mask() -> None:
    mask = object_mask()
    row = segment(scores_for(np.where(mask, 0, 1)))
    assert row["valid"] and row["correct"] and row["outcome"] == "correct" and row["iou"] == 1.0
    assert row["pred_pixels"] == row["true_pixels"] == mask.sum() and row["top1_label"] == "cup"
    assert np.array_equal(decode_mask(row["pred_mask"]), mask)


def test_segmentation_outcomes() -> None:
    mask = object_mask()
    missed = segment(scores_for(np.ones((H, W), dtype=int)))
    assert missed["outcome"] == "missed" and missed["iou"] == 0.0 and not missed["class_correct"]
    stray = np.where(mask, 1, 2)
    stray[0, 0] = 0  # one pixel of the object's class, elsewhere
    wrong_class = segment(scores_for(stray))
    assert wrong_class["outcome"] == "wrong_class" and wrong_class["top1_label"] == "dog"
    wrong_box = segment(scores_for(np.zeros((H, W), dtype=int)))  # everything is the object
    assert wrong_box["outcome"] == "wrong_box" and wrong_box["class_correct"]
    assert wrong_box["iou"] == pytest.approx(mask.sum() / (H * W))
    hidden = segment(scores_for(np.full((H, W), 2)), mask=np.zeros((H, W), dtype=bool))
    assert hidden["iou"] is None and not hidden["correct"] and hidden["top1_label"] == "cat"


def test_non_finite_scores_make_the_image_invalid() -> None:
    scores = scores_for(np.zeros((H, W), dtype=int))
    scores[1, 5, 5] = np.nan
    row = segment(scores)
    assert row["valid"] is False and all(v is None for k, v in row.items() if k != "valid")


@pytest.mark.torch
def test_segment_scores_from_resizes_and_reads_torchvision_dicts() -> None:
    import torch

    small = np.stack([np.full((4, 4), float(c)) for c in range(3)])[None].repeat(2, axis=0)
    out = segment_scores_from(small, 2, 3, (8, 6), "fcn")
    assert out.shape == (2, 3, 8, 6) and out.dtype == np.float32
    assert np.allclose(out[:, 2], 2.0) and np.allclose(out[:, 1], 1.0)
    same = segment_scores_from({"out": torch.from_numpy(small), "aux": None}, 2, 3, (4, 4), "fcn")
    assert same.dtype == np.float32 and np.array_equal(same, small)
    nan = small.copy()
    nan[0, 0, 0, 0] = np.nan
    assert np.isnan(segment_scores_from(nan, 2, 3, (4, 4), "fcn")[0, 0, 0, 0])  # the evaluator flags it


@pytest.mark.parametrize("output", [np.zeros((2, 3, 4)), np.zeros((1, 3, 4, 4)), np.zeros((2, 4, 4, 4)),
                                    {"aux": np.zeros((2, 3, 4, 4))}, [np.zeros((2, 3, 4, 4))]])
def test_segment_scores_from_refuses_bad_output_in_one_line(output: Any) -> None:
    with pytest.raises(UserError) as caught:
        segment_scores_from(output, 2, 3, (4, 4), "fcn")
    assert "\n" not in str(caught.value) and "'fcn'" in str(caught.value)


# -- average precision --------------------------------------------------------------------------
Image = list[tuple[float, float]]  # one image's matching detections: (score, IoU)


def ap_connection(rows: list[dict]) -> duckdb.DuckDBPyConnection:
    """A connection whose ``results`` are ``rows`` (object, c_a, detections; evaluable, valid default
    true), with the aggregate views on top."""
    con = duckdb.connect()
    con.execute("CREATE TABLE jobs (job BIGINT, object VARCHAR, environment VARCHAR, c_a INTEGER)")
    con.execute("CREATE TABLE result_rows (job BIGINT, valid BOOLEAN, correct BOOLEAN, evaluable BOOLEAN, "
                "det_scores FLOAT[], det_ious FLOAT[])")
    con.execute("CREATE VIEW results AS SELECT * FROM jobs JOIN result_rows USING (job)")
    assert register_views(con, ["c_a"])
    return load(con, rows)


def load(con: duckdb.DuckDBPyConnection, rows: list[dict]) -> duckdb.DuckDBPyConnection:
    """Replace the rows behind ``con``'s ``results`` (its views read them live)."""
    con.execute("DELETE FROM jobs")
    con.execute("DELETE FROM result_rows")
    for job, row in enumerate(rows):
        found = sorted(row["detections"], key=lambda d: -d[0])
        con.execute("INSERT INTO jobs VALUES (?, ?, 'env', ?)", [job, row.get("object", "cup"), row.get("c_a", 0)])
        con.execute("INSERT INTO result_rows VALUES (?, ?, false, ?, ?, ?)",
                    [job, row.get("valid", True), row.get("evaluable", True), [s for s, _ in found],
                     [i for _, i in found]])
    return con


@functools.cache
def shared() -> duckdb.DuckDBPyConnection:
    """One connection with the views for the property tests: creating the views costs more than a query."""
    return ap_connection([])


def ap_rows(con: duckdb.DuckDBPyConnection, sql: str) -> dict[Any, dict]:
    cursor = con.execute(sql)
    names = [d[0] for d in cursor.description]
    rows = [dict(zip(names, r)) for r in cursor.fetchall()]
    return {(r.get("level"), r["object"]) if "level" in r else r["object"]: r for r in rows}


def reference_ap(images: list[Image], threshold: float) -> float:
    """COCO's AP of one object's images (each one true box), written the plain way."""
    ranked = []
    for job, found in enumerate(images):
        found = sorted(((float(np.float32(s)), float(np.float32(i))) for s, i in found), key=lambda d: -d[0])
        hits = [n for n, (_, iou) in enumerate(found) if iou >= threshold]
        ranked += [(-score, job, n, bool(hits) and n == hits[0]) for n, (score, _) in enumerate(found)]
    ranked.sort()
    tp = np.cumsum([hit for *_, hit in ranked])
    precision = tp / np.arange(1, len(ranked) + 1)
    envelope = np.maximum.accumulate(precision[::-1])[::-1]
    total = 0.0
    for r in range(101):
        reached = np.flatnonzero(tp * 100 >= r * len(images))
        total += envelope[reached[0]] if len(reached) else 0.0
    return total / 101


THRESHOLDS = [(50 + 5 * s) / 100 for s in range(10)]


def test_ap_by_hand() -> None:
    cup: list[Image] = [[(0.9, 0.72), (0.6, 0.62)], [(0.8, 0.3), (0.7, 0.88)], [(0.5, 0.97)], []]
    rows = [{"detections": d} for d in cup]
    rows += [{"detections": [(0.95, 1.0)], "evaluable": False},  # not evaluable: ignored
             {"detections": [(0.99, 1.0)], "valid": False},  # invalid: ignored
             {"detections": [(0.99, 1.0)], "evaluable": None},  # truth still missing: counted
             {"object": "mug", "detections": [(1.0, 1.0)]}]
    con = ap_connection(rows)
    got = ap_rows(con, "FROM average_precision")
    # The cup's five evaluable images (the last with a perfect box at 0.99); its detections by score:
    #   0.99 (iou 1), 0.9 (.72), 0.8 (.3), 0.7 (.88), 0.6 (.62, second in its image), 0.5 (.97).
    # 5 positives. t ≤ 0.70: TP TP FP TP FP TP (0.6 is its image's second hit, a false positive);
    #   precision 1, 1, 2/3, 3/4, 3/5, 4/6; monotone: 1, 1, 3/4, 3/4, 2/3, 2/3.
    #   recall 0.2 at rank 1, 0.4 at 2, 0.6 at 4, 0.8 at 6: points 0..40 → 1, 41..60 → 3/4,
    #   61..80 → 2/3, 81..100 → 0 (the missed image).
    low = (41 * 1 + 20 * 3 / 4 + 20 * 2 / 3) / 101
    # 0.75 ≤ t ≤ 0.85: 0.9 misses (.72): TP FP FP TP FP TP → precision 1, 1/2, 1/3, 2/4, 2/5, 3/6;
    #   monotone 1, 1/2, 1/2, 1/2, 1/2, 1/2: points 0..20 → 1, 21..40 → 1/2, 41..60 → 1/2.
    mid = (21 * 1 + 20 * 0.5 + 20 * 0.5) / 101
    # t ≥ 0.90: 0.7 misses too (.88): TP FP FP FP FP TP → 1, 1/2, 1/3, 1/4, 1/5, 2/6;
    #   monotone 1, 1/2, 1/3, 1/3, 1/3, 1/3: points 0..20 → 1, 21..40 → 1/3.
    high = (21 * 1 + 20 / 3) / 101
    assert got["cup"]["images"] == 5
    assert got["cup"]["ap50"] == pytest.approx(low)
    assert got["cup"]["ap75"] == pytest.approx(mid)
    assert got["cup"]["ap"] == pytest.approx((5 * low + 3 * mid + 2 * high) / 10)
    cup_images = cup + [[(0.99, 1.0)]]
    assert got["cup"]["ap"] == pytest.approx(np.mean([reference_ap(cup_images, t) for t in THRESHOLDS]))
    assert got["mug"]["ap50"] == got["mug"]["ap"] == 1.0
    assert got[None]["images"] == 6 and got[None]["ap50"] == pytest.approx((low + 1) / 2)
    assert list(got) == [None, "cup", "mug"]


def test_the_oracle_has_ap_1_and_the_shifted_oracle_ap50_0() -> None:
    shifted = 0.4 / 1.6
    rows = ([{"detections": [(1.0, 1.0)], "c_a": 0, "object": o} for o in ("cup", "mug") for _ in range(3)]
            + [{"detections": [(1.0, shifted)], "c_a": 1, "object": o} for o in ("cup", "mug") for _ in range(3)])
    con = ap_connection(rows)
    by_level = ap_rows(con, "FROM average_precision_by_value WHERE parameter = 'c_a'")
    assert {k: (r["images"], r["ap50"], r["ap75"], r["ap"]) for k, r in by_level.items() if k[1] is None} == {
        (0, None): (6, 1.0, 1.0, 1.0), (1, None): (6, 0.0, 0.0, 0.0)}
    assert by_level[(0, "mug")]["ap"] == 1.0 and by_level[(1, "cup")]["label"] == "1"
    overall = ap_rows(con, "FROM average_precision")
    # Per object: 3 hits then 3 misses, all at score 1 (ties ranked by job): recall 0.5 at precision 1.
    assert overall[None]["ap50"] == pytest.approx(51 / 101)
    assert ap_rows(con, "FROM average_precision_by_value WHERE parameter = 'object'")[(0, None)]["images"] == 6


def test_no_views_without_detections() -> None:
    con = duckdb.connect()
    con.execute("CREATE TABLE jobs AS SELECT 0::BIGINT AS job, 'cup' AS object, 'env' AS environment")
    con.execute("CREATE VIEW results AS SELECT *, true AS valid, true AS correct FROM jobs")
    assert register_views(con, [])
    views = {r[0] for r in con.execute("SELECT view_name FROM duckdb_views() WHERE NOT internal").fetchall()}
    assert "control_accuracy" in views and "average_precision" not in views


detections = st.lists(st.tuples(st.floats(0, 1, width=32), st.sampled_from([0.0, 0.3, 0.5, 0.62, 0.8, 1.0])),
                      max_size=3)
tables = st.lists(st.tuples(st.sampled_from(["cup", "mug"]), detections, st.booleans()), min_size=1, max_size=6)


@settings(max_examples=50, deadline=None)
@given(tables)
def test_ap_is_a_finite_fraction_and_coco_s(table: list[tuple[str, Image, bool]]) -> None:
    con = load(shared(), [{"object": o, "detections": d, "evaluable": e} for o, d, e in table])
    got = ap_rows(con, "FROM average_precision")
    for obj in {o for o, _, e in table if e}:
        images = [d for o, d, e in table if o == obj and e]
        assert got[obj]["images"] == len(images)
        assert got[obj]["ap50"] == pytest.approx(reference_ap(images, 0.5))
        assert got[obj]["ap"] == pytest.approx(np.mean([reference_ap(images, t) for t in THRESHOLDS]))
    for row in got.values():
        for key in ("ap50", "ap75", "ap"):
            assert math.isfinite(row[key]) and 0.0 <= row[key] <= 1.0


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(0.5, 1, width=32), detections.map(lambda d: [(s / 4, i) for s, i in d])),
                min_size=1, max_size=6))
def test_ap_is_1_when_every_image_s_top_detection_is_perfect(table: list[tuple[float, Image]]) -> None:
    # Each image's perfect box scores at least 0.5 and its others below 0.25, so every true
    # positive outranks every false one.
    con = load(shared(), [{"detections": [(top, 1.0), *rest]} for top, rest in table])
    row = ap_rows(con, "FROM average_precision")["cup"]
    assert row["ap50"] == row["ap75"] == row["ap"] == 1.0
