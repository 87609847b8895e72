"""Jobs that are not evaluable, box and mask outcomes, IoU, and boxes drawn on thumbnails.

The stores here are written row by row (a jobs file planned with the mask pass, truth rows,
predictions with the columns a localization or segmentation evaluator writes, small image and
mask blobs), so each test knows the answer by hand: which jobs are out of frame or hidden, what
each value's outcomes are, the IoUs. No Blender, no model; the browser test draws the page.
"""

from __future__ import annotations

import base64
import io
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest
from PIL import Image

from sweep3d.cache.store import Store
from sweep3d.cli.output import not_evaluable_line
from sweep3d.core.truth import encode_mask
from sweep3d.report import build_context, render_html, write_report
from sweep3d.report.overlays import PRED_COLOR, TRUE_COLOR, Overlay, read_overlays
from sweep3d.report.panels import CORE_PANELS, PANELS
from sweep3d.report.reading import CORRECT, NOT_EVALUABLE, WRONG, Results, materialise_views
from sweep3d.report.thumbs import encode_thumbnail
from sweep3d.results import connect, stored_summary, summarise
from sweep3d.results.measures import MEASURES
from sweep3d.results.task_views import OUTCOMES, TASK_VIEWS
from sweep3d.spec.columns import MIN_VISIBLE_METADATA, MODELS_METADATA, PARAMETERS_METADATA
from tests.helpers import (
    MIN_VISIBLE,
    PARAMETERS,
    T0,
    TASKS_SPEC,
    TRUE_BOX,
    H,
    Job,
    W,
    assert_clean,
    build_store,
    load_spec,
    open_page,
    pred_box,
    prediction,
    synthetic_jobs,
    write_spec,
)


def make_store(folder: Path, jobs: list[Job], kind: str = "localization", models: tuple[str, ...] = ("m",),
               images: bool = False, framed: bool = True) -> Path:
    """A spec and a store holding ``jobs`` with the columns of ``kind``'s evaluator (``localization``,
    ``detection`` (its box columns only), ``segmentation``, or ``classification``: none of the box or
    mask columns); returns the spec. Without ``framed``, the truth rows are from before ``framed_pixels``."""
    folder.mkdir(parents=True, exist_ok=True)
    spec = write_spec(folder, TASKS_SPEC)
    store = Store(folder / "store")
    rows, truths, predictions = [], [], []
    for model in models:
        for job in jobs:
            key = f"{model}-{job.job}" if len(models) > 1 else f"k{job.job}"
            render = f"r{job.job}"
            row = {"experiment": "tasks", "job": job.job, "object": job.object, "environment": "white",
                   "orientation_yaw": job.yaw, "blur_sigma": job.sigma, "render_key": render, "image_key": render,
                   "pred_key": key, "truth_key": f"t{job.job}" if job.in_frame else None, "in_frame": job.in_frame}
            rows.append({**row, "model": model} if len(models) > 1 else row)
            if job.in_frame:
                predictions.append(prediction(key, render, job, kind, model))
    for job in jobs:
        if job.in_frame and job.truth:
            truths.append({"truth_key": f"t{job.job}", "render_key": f"r{job.job}", "passes": ["mask"],
                           **dict(zip(("gt_x0", "gt_y0", "gt_x1", "gt_y1"), TRUE_BOX if job.visible else [None] * 4)),
                           "visible_pixels": job.visible, "silhouette_pixels": 750, "framed_pixels": job.framed,
                           "visible_fraction": job.fraction, "created_at": T0})
    metadata = {PARAMETERS_METADATA: json.dumps(PARAMETERS).encode(), MIN_VISIBLE_METADATA: str(MIN_VISIBLE).encode()}
    if len(models) > 1:
        metadata[MODELS_METADATA] = json.dumps(list(models)).encode()
    store.write_table_file(store.jobs_path("tasks"), pa.Table.from_pylist(rows).replace_schema_metadata(metadata))
    store.append("predictions", predictions)
    store.append("truths", truths if framed else [{k: v for k, v in t.items() if k != "framed_pixels"} for t in truths])
    if images:
        write_blobs(store, jobs)
    return spec




def write_blobs(store: Store, jobs: list[Job]) -> None:
    """A grey image per render and, per truth row, the true mask (the box, filled)."""
    for job in jobs:
        path = store.blob_path(f"r{job.job}")
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.new("RGB", (W, H), (128, 128, 128)).save(path)
        mask = np.zeros((H, W), bool)
        x0, y0, x1, y1 = TRUE_BOX
        mask[y0:y1, x0:x1] = job.visible > 0
        path = store.blob_path(f"t{job.job}", "mask.png")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(encode_mask(mask))


def rows_of(con, sql: str, params: list | None = None) -> list[dict[str, Any]]:
    cursor = con.execute(sql, params or [])
    names = [d[0] for d in cursor.description]
    return [dict(zip(names, r)) for r in cursor.fetchall()]


def opened(spec: Path):
    loaded = load_spec(spec)
    store = Store(loaded.store)
    return loaded, connect(store, loaded.name), store


# -- the gate -----------------------------------------------------------------------------------


def test_unevaluable_jobs_are_never_averaged_and_are_counted_apart_with_their_reason(tmp_path: Path) -> None:
    jobs = synthetic_jobs()
    _, con, store = opened(make_store(tmp_path, jobs))
    counted = [j for j in jobs if j.counted]
    assert {j.evaluable for j in jobs} == {True, False, None} and len(counted) < sum(j.valid for j in jobs)
    assert con.execute("SELECT count(*) FROM results WHERE counted").fetchone()[0] == len(counted)

    summary = summarise(con, PARAMETERS)
    assert summary.counted == len(counted) and summary.correct == sum(j.outcome == "correct" for j in counted)
    assert summary.accuracy == pytest.approx(summary.correct / len(counted))
    unevaluable = [j for j in jobs if j.evaluable is False]
    assert summary.not_evaluable == len(unevaluable) and summary.min_visible == MIN_VISIBLE
    assert summary.not_evaluable_reasons == {
        reason: sum(j.reason == reason for j in unevaluable) for reason in ("fully occluded", "hidden", "out of frame")}
    assert summary.invalid == sum(not j.valid and j.evaluable is not False for j in jobs)
    assert summary.counted + summary.invalid + summary.not_evaluable == len(jobs)
    assert all(f["job"] in {j.job for j in counted} for f in summary.failures)

    for row in rows_of(con, "FROM control_accuracy WHERE parameter = 'orientation_yaw'"):
        here = [j for j in counted if j.yaw == float(row["label"])]
        assert (row["n"], row["n_correct"]) == (len(here), sum(j.outcome == "correct" for j in here))
    scene = rows_of(con, "FROM scene_accuracy WHERE object = 'mug'")[0]
    assert scene["n"] == sum(j.object == "mug" for j in counted)
    confusions = {r["prediction"] for r in rows_of(con, "FROM object_confusions")}
    assert "teapot" in confusions and "hidden thing" not in confusions  # the hidden jobs' answers
    overall = sum(j.outcome == "correct" for j in counted) / len(counted)
    assert all(m["accuracy"] < overall for m in rows_of(con, "FROM failure_modes(min_count := 2)"))

    found = {(r["object"], r["reason"]): r for r in rows_of(con, "FROM not_evaluable")}
    expected: dict[tuple[str, str], int] = {}
    for j in unevaluable:
        expected[j.object, j.reason] = expected.get((j.object, j.reason), 0) + 1
    assert {k: r["n"] for k, r in found.items()} == expected
    assert all(r["min_visible"] == MIN_VISIBLE and r["object_jobs"] == 36 for r in found.values())
    assert found["mug", "out of frame"]["share"] == pytest.approx(expected["mug", "out of frame"] / 36)
    assert stored_summary(store, "tasks", PARAMETERS).not_evaluable == len(unevaluable)


def test_truth_rows_from_before_framed_pixels_call_an_unseen_object_in_frame_fully_occluded(tmp_path: Path) -> None:
    """Such a row cannot tell an occluder from a frame's edge that cuts all of the object off: in
    frame by the plan's geometry and not a pixel visible reads as fully occluded."""
    jobs = synthetic_jobs()
    _, con, _ = opened(make_store(tmp_path, jobs, framed=False))
    found = {r["reason"]: r["n"] for r in rows_of(con, "SELECT reason, sum(n)::BIGINT AS n FROM not_evaluable GROUP BY 1")}
    unseen = [j for j in jobs if j.in_frame and j.truth and j.visible == 0]
    assert {j.job for j in unseen} == {4, 10} and found["fully occluded"] == len(unseen)
    assert found["out of frame"] == sum(not j.in_frame for j in jobs)


def test_the_explorer_counts_and_galleries_leave_unevaluable_jobs_out(tmp_path: Path) -> None:
    jobs = synthetic_jobs()
    loaded, con, _ = opened(make_store(tmp_path, jobs))
    materialise_views(con)
    results = Results(con, ["object", "environment", *loaded.parameter_columns])
    counts = results.counts([])
    counted = [j for j in jobs if j.counted]
    assert (counts["n"], counts["k"]) == ([len(counted)], [sum(j.outcome == "correct" for j in counted)])
    assert counts["total"] == [sum(j.in_frame for j in jobs)]  # every result, counted or not
    hidden = [j.job for j in jobs if j.in_frame and j.evaluable is False]
    assert {r.outcome for r in results.rows(hidden)} == {NOT_EVALUABLE}
    assert not set(hidden) & {r.job for r in results.examples({}, 100, WRONG)}
    assert not set(hidden) & {r.job for r in results.examples({}, 100, CORRECT)}


def test_two_models_are_compared_on_evaluable_jobs_only(tmp_path: Path) -> None:
    jobs = synthetic_jobs()
    _, con, _ = opened(make_store(tmp_path, jobs, models=("a", "b")))
    both = [j for j in jobs if j.counted]
    agreement = rows_of(con, "FROM model_agreement")[0]
    assert agreement["n"] == len(both)
    assert {r["model"]: r["n"] for r in rows_of(con, "FROM model_accuracy")} == {"a": len(both), "b": len(both)}
    per_model = {r["reason"]: r["n"] for r in rows_of(con, "SELECT reason, sum(n) AS n FROM not_evaluable GROUP BY 1")}
    assert sum(per_model.values()) == sum(j.evaluable is False for j in jobs)  # one model's jobs, not both


def test_the_printed_findings_say_how_many_were_not_evaluable_and_why(tmp_path: Path) -> None:
    jobs = synthetic_jobs()
    spec = make_store(tmp_path, jobs)
    summary = stored_summary(Store(tmp_path / "store"), "tasks", PARAMETERS)
    line = not_evaluable_line(summary)
    hidden = sum(j.evaluable is False and j.reason == "hidden" for j in jobs)
    out = sum(j.evaluable is False and j.reason == "out of frame" for j in jobs)
    occluded = sum(j.evaluable is False and j.reason == "fully occluded" for j in jobs)
    assert occluded == 1 and line == (f"{hidden + out + occluded} jobs not evaluable, excluded: {occluded} fully occluded, "
                                      f"{hidden} hidden (< 20% visible), {out} out of frame")
    assert load_spec(spec).name == "tasks"


# -- box and mask views -------------------------------------------------------------------------


def test_outcomes_by_value_shares_sum_to_one_and_match_a_hand_count(tmp_path: Path) -> None:
    jobs = synthetic_jobs()
    _, con, _ = opened(make_store(tmp_path, jobs))
    rows = rows_of(con, "FROM outcomes_by_value")
    levels = {(r["parameter"], r["level"]) for r in rows_of(con, "FROM control_accuracy")
              if r["parameter"] not in MEASURES}  # a measure (the IoU) is an axis, not a value with outcomes
    assert {(r["parameter"], r["level"]) for r in rows} == levels  # the same levels as control_accuracy
    for row in rows:
        assert sum(row[f"share_{o}"] for o in OUTCOMES) == pytest.approx(1.0)
    counted = [j for j in jobs if j.counted]
    for row in (r for r in rows if r["parameter"] == "orientation_yaw"):
        here = [j for j in counted if j.yaw == float(row["label"])]
        assert row["n"] == len(here)
        for outcome in OUTCOMES:
            n = sum(j.outcome == outcome for j in here)
            assert row[f"n_{outcome}"] == n and row[f"share_{outcome}"] == pytest.approx(n / len(here))
    accuracy = {r["label"]: r["accuracy"] for r in rows_of(con, "FROM control_accuracy WHERE parameter = 'object'")}
    for row in (r for r in rows if r["parameter"] == "object"):
        assert row["share_correct"] == pytest.approx(accuracy[row["label"]])


def test_iou_by_object_quantiles_are_numpy_s_with_a_miss_as_0(tmp_path: Path) -> None:
    jobs = synthetic_jobs()
    _, con, _ = opened(make_store(tmp_path, jobs))
    rows = {r["object"]: r for r in rows_of(con, "FROM iou_by_object")}
    assert set(rows) == {"mug", "ball"}
    for name, row in rows.items():
        mine = [j for j in jobs if j.counted and j.object == name]
        values = np.array([0.0 if j.iou is None else j.iou for j in mine])
        assert row["misses"] == sum(j.iou is None for j in mine) > 0  # the misses are in, at 0
        assert row["n"] == len(values) and row["mean"] == pytest.approx(values.mean())
        for column, q in (("p10", 10), ("p25", 25), ("median", 50), ("p75", 75), ("p90", 90)):
            assert row[column] == pytest.approx(np.percentile(values, q), abs=1e-12), column


def test_views_exist_only_with_their_columns(tmp_path: Path) -> None:
    jobs = synthetic_jobs()
    present = {}
    for kind in ("classification", "localization", "detection", "segmentation"):
        _, con, _ = opened(make_store(tmp_path / kind, jobs, kind))
        present[kind] = {v for v in TASK_VIEWS
                         if con.execute("SELECT count(*) FROM duckdb_views() WHERE view_name = ?", [v]).fetchone()[0]}
    assert present["classification"] == {"not_evaluable"}
    assert present["localization"] == present["detection"] == present["segmentation"] == set(TASK_VIEWS)


# -- thumbnails ---------------------------------------------------------------------------------


def decoded(uri: str) -> np.ndarray:
    with Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1]))) as img:
        return np.asarray(img.convert("RGB"), dtype=np.int32)


def hue(pixel: np.ndarray, color: tuple[int, int, int]) -> bool:
    """Whether ``pixel`` is clearly ``color`` (pure green or red), JPEG error allowed."""
    channel = int(np.argmax(color))
    others = [c for c in range(3) if c != channel]
    return pixel[channel] > 150 and all(pixel[channel] - pixel[c] > 90 for c in others)


def edge(box: tuple[float, ...], scale: float) -> list[tuple[int, int]]:
    """(x, y) thumbnail pixels along the middle of each side of ``box`` scaled by ``scale``, one pixel inside."""
    x0, y0, x1, y1 = (round(v * scale) for v in box)
    xm, ym = (x0 + x1) // 2, (y0 + y1) // 2
    return [(x0, ym), (x1 - 1, ym), (xm, y0), (xm, y1 - 1)]


def test_a_thumbnail_shows_the_true_box_in_green_and_the_predicted_one_in_red(tmp_path: Path) -> None:
    path = tmp_path / "grey.png"
    Image.new("RGB", (200, 150), (128, 128, 128)).save(path)
    truth, predicted = (20, 30, 100, 110), (110.0, 20.0, 180.0, 90.0)
    uri, problem = encode_thumbnail(path, set(), 96, Overlay(true_box=truth, pred_box=predicted))
    assert problem is None
    pixels = decoded(uri)
    assert pixels.shape == (72, 96, 3)  # scaled by 96 / 200
    for x, y in edge(truth, 96 / 200):
        assert hue(pixels[y, x], TRUE_COLOR), (x, y, pixels[y, x])
    for x, y in edge(predicted, 96 / 200):
        assert hue(pixels[y, x], PRED_COLOR), (x, y, pixels[y, x])
    centre = pixels[35, 28]  # inside the true box: untouched grey
    assert abs(centre - 128).max() < 12
    plain, _ = encode_thumbnail(path, set(), 96)
    assert not any(hue(p, TRUE_COLOR) or hue(p, PRED_COLOR) for p in decoded(plain).reshape(-1, 3))


def test_segmentation_thumbnails_tint_the_true_mask_green_and_the_predicted_one_red(tmp_path: Path) -> None:
    path, mask_path = tmp_path / "grey.png", tmp_path / "mask.png"
    Image.new("RGB", (W, H), (128, 128, 128)).save(path)
    true_mask, pred_mask = np.zeros((H, W), bool), np.zeros((H, W), bool)
    true_mask[4:20, 4:28] = True
    pred_mask[28:44, 36:60] = True
    mask_path.write_bytes(encode_mask(true_mask))
    uri, _ = encode_thumbnail(path, set(), 64, Overlay(true_mask=mask_path, pred_mask=encode_mask(pred_mask)))
    pixels = decoded(uri)
    green, red, grey = pixels[12, 16], pixels[36, 48], pixels[24, 32]
    assert green[1] - green[0] > 40 and green[1] - green[2] > 40
    assert red[0] - red[1] > 40 and red[0] - red[2] > 40
    assert abs(grey - 128).max() < 12


def test_the_report_draws_boxes_on_its_thumbnails(tmp_path: Path) -> None:
    jobs = synthetic_jobs()
    loaded, con, store = opened(make_store(tmp_path, jobs, images=True))
    overlays = read_overlays(con, store, [f"r{j.job}" for j in jobs])
    wrong_box = next(j for j in jobs if j.counted and j.outcome == "wrong_box")
    assert overlays[f"r{wrong_box.job}"].true_box == TRUE_BOX
    assert overlays[f"r{wrong_box.job}"].pred_box == pred_box(wrong_box)
    context = build_context(loaded, con, store)
    uris = json.loads(context["thumbs"])
    card = next(p for p in context["panels"] if p.id == "failures").data["cards"][0]
    pixels = decoded(uris[card["thumb"]])
    assert any(hue(p, TRUE_COLOR) for p in pixels.reshape(-1, 3))
    job = next(j for j in jobs if j.job == card["job"])
    if pred_box(job) is not None:
        assert any(hue(p, PRED_COLOR) for p in pixels.reshape(-1, 3))


# -- the report ---------------------------------------------------------------------------------


def panel(context: dict[str, Any], panel_id: str):
    return next((p for p in context["panels"] if p.id == panel_id), None)


def test_the_report_shows_what_was_not_evaluable_and_how_boxes_fail(tmp_path: Path) -> None:
    jobs = synthetic_jobs()
    loaded, con, store = opened(make_store(tmp_path, jobs))
    context = build_context(loaded, con, store)
    ids = [p.id for p in context["panels"]]
    assert ids[:4] == ["findings", "explorer", "overall", "not-evaluable"] and "outcomes" in ids  # after the first screen
    counted, unevaluable = sum(j.counted for j in jobs), sum(j.evaluable is False for j in jobs)
    html = render_html(context)
    detail = re.search(r'id="accuracy-detail">(.*?)</div>', html, re.S).group(1)
    assert re.sub(r"\s+", " ", re.sub(r"<[^>]+>", "", detail)) == (
        f"{context['summary'].correct} correct of {counted} evaluated of {len(jobs)} jobs; {unevaluable} not evaluable")
    data = panel(context, "not-evaluable").data
    assert data["total"] == unevaluable and data["min_visible"] == "20%"
    assert {r["reason"]: r["n"] for r in data["reasons"]} == context["summary"].not_evaluable_reasons
    outcomes = panel(context, "outcomes").data
    assert len(outcomes["outcomes"]) == 3 and outcomes["iou"] is not None  # object, yaw, blur (one environment)
    figure = json.loads(outcomes["outcomes"][0].json)
    assert [t["name"] for t in figure["data"]] == ["correct", "wrong class", "right class, wrong box", "missed"]
    assert "FROM outcomes_by_value" in outcomes["outcomes"][0].query
    assert "FROM not_evaluable" in html and "FROM iou_by_object" in html
    for view in TASK_VIEWS:
        assert f"<code>{view}</code>" in html


def test_box_task_panels_say_the_task_s_measure_and_why_each_failure_failed(tmp_path: Path) -> None:
    jobs = synthetic_jobs()
    spec = make_store(tmp_path, jobs, "detection")
    spec.write_text(spec.read_text().replace("[evaluator]\n", '[evaluator]\nkind = "detection"\n'))
    loaded, con, store = opened(spec)
    context = build_context(loaded, con, store)
    html = render_html(context)
    assert context["measure"] == ("detection accuracy", "a kept box of the object's class with IoU ≥ 0.5")
    assert re.search(r'id="measure"[^>]*>detection accuracy<', html)
    # "Taken for" lists wrong classes only; the right-class failures are counted beside them
    counted = [j for j in jobs if j.counted]
    for row in panel(context, "objects").data["objects"]:
        mine = [j for j in counted if j.object == row["object"]]
        wrong_class = sum(j.outcome == "wrong_class" for j in mine)
        assert sum(c["count"] for c in row["confusions"]) == wrong_class
        said = dict(reversed(text.split(" ", 1)) for text in row["box_failures"])
        assert said == {o.replace("_", " "): str(n) for o in ("wrong_box", "missed")
                        if (n := sum(j.outcome == o for j in mine))}
    # the worst failures: lowest IoU first (misses first), and no claim about a loss
    failures = panel(context, "failures").data
    assert failures["order"] == "with the lowest IoU (misses first)" and "highest loss" not in failures["order"]
    ious = [c["outcome"] for c in failures["cards"]]
    assert ious[0].startswith("missed")
    # every tile of a failure says how it failed
    mode_tiles = [t for m in panel(context, "failure-modes").data["modes"] for t in m["examples"]]
    example = next(t for t in mode_tiles + [c for r in panel(context, "objects").data["objects"]
                                            for c in (x["example"] for x in r["confusions"]) if c])
    assert any(why in example["caption"] for why in ("wrong class", "wrong box · IoU", "missed"))
    explorer = panel(context, "explorer").data
    whys = explorer["whys"] if "whys" in explorer else json.loads(explorer["json"])["whys"]
    assert whys and all(w.split(" · ")[0] in ("wrong class", "wrong box", "missed") for w in whys)


def test_a_classification_store_without_unevaluable_jobs_gets_the_report_it_got_before(tmp_path: Path) -> None:
    spec = build_store(tmp_path / "plain", 300, seed=2, images=False)  # no truth, no box columns
    loaded, con, store = opened(spec)
    context = build_context(loaded, con, store)
    # its elevation and blur are lists of numbers: the failure boundaries panel is the one added
    assert [p.id for p in context["panels"]] == [p.id for p in PANELS if p in CORE_PANELS or p.id == "boundaries"]
    html = render_html(context)
    markup = re.sub(r"<(script|style)\b.*?</\1>", "", html, flags=re.S)  # the page's own CSS and JS name them
    for text in ("not-evaluable", "not evaluable", 'id="outcomes"', "fig-iou", "fig-outcome-", "counted"):
        assert text not in markup
    assert not [v for v in TASK_VIEWS if f"<code>{v}</code>" in html]
    summary = context["summary"]
    assert summary.counted == summary.evaluated - summary.invalid and summary.not_evaluable == 0

    jobs = [j for j in synthetic_jobs() if j.evaluable is not False]  # truth passes, every job evaluable
    loaded, con, store = opened(make_store(tmp_path / "truth", jobs, "classification"))
    ids = [p.id for p in build_context(loaded, con, store)["panels"]]
    assert ids == [p.id for p in PANELS if p in CORE_PANELS or p.id == "boundaries"]


@pytest.mark.browser
def test_the_new_panels_draw_in_chromium(tmp_path: Path, chromium) -> None:
    spec = make_store(tmp_path, synthetic_jobs(), "detection", images=True)
    spec.write_text(spec.read_text().replace("[evaluator]\n", '[evaluator]\nkind = "detection"\n'))
    path = write_report(load_spec(spec))
    with open_page(chromium, path) as (page, events):
        assert page.text_content("#measure") == "detection accuracy"  # the task's own measure, in the headline
        assert "IoU ≥ 0.5" in page.text_content("#measure-rule")
        ticks = page.evaluate("Array.from(document.querySelectorAll('#fig-iou .xtick text')).map(t => t.textContent)")
        assert ticks and all("missed)" in t for t in ticks)  # the misses are in the box plot, at IoU 0
        drawn = set(page.evaluate(
            "Array.from(document.querySelectorAll('.js-plotly-plot')).filter(d => d.querySelector('svg.main-svg'))"
            ".map(d => d.id)"))
        assert {"fig-not-evaluable", "fig-iou", "fig-outcome-1"} <= drawn
        bars = page.evaluate("document.querySelectorAll('#fig-outcome-1 .bars .point').length")
        assert bars >= 4  # stacked outcomes at each value
        boxes = page.evaluate("document.querySelectorAll('#fig-iou .boxes path').length")
        assert boxes >= 2  # one per object
        assert "not evaluable" in page.inner_text("#not-evaluable")
        assert "not evaluable" in page.inner_text("#accuracy-detail")
        assert_clean(path, events)


def test_a_segmentation_report_tints_its_thumbnails_and_says_how_each_failure_failed(tmp_path: Path) -> None:
    jobs = synthetic_jobs()
    loaded, con, store = opened(make_store(tmp_path, jobs, "segmentation", images=True))
    context = build_context(loaded, con, store)
    cards = panel(context, "failures").data["cards"]
    assert cards and all(c["outcome"].split(" · ")[0] in ("wrong class", "wrong box", "missed") for c in cards)
    uris = json.loads(context["thumbs"])
    wrong_box = next(c for c in cards if c["outcome"].startswith("wrong box"))
    pixels = decoded(uris[wrong_box["thumb"]])
    # the predicted mask (the true box shifted right) shows red beyond the true mask's green
    assert any(p[0] - p[1] > 40 and p[0] - p[2] > 40 for p in pixels.reshape(-1, 3))
    assert any(p[1] - p[0] > 40 and p[1] - p[2] > 40 for p in pixels.reshape(-1, 3))


def test_query_reads_the_new_views_read_only(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from sweep3d.cli import app

    spec = make_store(tmp_path, synthetic_jobs())
    for view in TASK_VIEWS:
        out = tmp_path / f"{view}.json"
        result = CliRunner().invoke(app, ["query", str(spec), f"FROM {view}", "-o", str(out)])
        assert result.exit_code == 0, result.output
        assert json.loads(out.read_text())
    result = CliRunner().invoke(app, ["query", str(spec), "SELECT count(*) AS n FROM results WHERE counted",
                                      "--format", "csv"])
    assert result.exit_code == 0 and result.output.split() == ["n", str(sum(j.counted for j in synthetic_jobs()))]


def test_a_detection_report_without_ranked_classes_builds_every_panel(tmp_path: Path) -> None:
    jobs = synthetic_jobs()
    loaded, con, store = opened(make_store(tmp_path, jobs, "detection", images=True))
    context = build_context(loaded, con, store)
    ids = {p.id for p in context["panels"]}
    assert {"not-evaluable", "outcomes", "failures"} <= ids
    card = panel(context, "failures").data["cards"][0]
    assert card["loss"] == "" and [t["label"] for t in card["topk"]] and card["outcome"]
    assert context["summary"].counted == sum(j.counted for j in jobs)
