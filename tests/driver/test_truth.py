"""Ground-truth passes on demand: the object mask and depth, the true box, the visible fraction and
the validity gate (``evaluable``), their spec keys and their cache keys.

Real Blender renders of a cube at 48×48 (1 sample) and the real classifier for the end-to-end ones.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.core.errors import SpecError
from sweep3d.core.truth import box, decode_depth, decode_mask, encode_depth, encode_mask, ground_truth
from sweep3d.driver.passes import needed_passes, truth_passes
from sweep3d.results import connect as connect_results
from tests.helpers import load_spec, plan_for, spec_toml, write_spec

SIDE = 48
TRUTH_SPEC = spec_toml("truth", seed=3, render={"resolution": SIDE, "samples": 1, "denoise": False}, body="""\
[[controls]]
type = "position"
x = [0.0, 0.5, 1.6, 2.5]

[[controls]]
type = "occlusion"
coverage = [0.0, 0.5]

[policy]
type = "grid"

[evaluator]
passes = ["mask", "depth"]
""")
PLAIN_SPEC = TRUTH_SPEC.replace('passes = ["mask", "depth"]\n', "")


def run_cli(spec: Path) -> None:
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output


def stage_counts(spec: Path) -> dict[str, int]:
    from sweep3d.runner.pipeline import run

    outcome = run(load_spec(spec))
    return {s: outcome.outcome(s).computed for s in ("render", "infer")}


# -- fast: the spec keys, the pass API, the numbers ---------------------------------------------
def test_passes_and_min_visible_load_and_bad_values_are_one_line(tmp_path: Path) -> None:
    spec = load_spec(write_spec(tmp_path, TRUTH_SPEC))
    assert needed_passes(spec) == ("depth", "mask") and spec.evaluator.min_visible == 0.1
    depth_only = load_spec(write_spec(tmp_path, TRUTH_SPEC.replace('["mask", "depth"]', '["depth"]'), name="d.toml"))
    assert truth_passes(depth_only) == ("depth", "mask")  # the ground-truth numbers come from the mask
    assert needed_passes(load_spec(write_spec(tmp_path, PLAIN_SPEC, name="p.toml"))) == ()
    for bad, where in (('passes = ["mask", "normals"]', "evaluator.passes"),
                       ('passes = "mask"', "evaluator.passes"),
                       ('passes = ["mask"]\nmin_visible = 1.5', "evaluator.min_visible")):
        path = write_spec(tmp_path, TRUTH_SPEC.replace('passes = ["mask", "depth"]', bad), name="bad.toml")
        with pytest.raises(SpecError) as caught:
            load_spec(path)
        message = str(caught.value)
        assert "\n" not in message and where in message and "bad.toml" in message, message


def test_truth_keys_leave_every_other_key_and_the_plain_jobs_table_alone(tmp_path: Path) -> None:
    plain = plan_for(load_spec(write_spec(tmp_path, PLAIN_SPEC, name="p.toml")), model_digest="m")
    truth = plan_for(load_spec(write_spec(tmp_path, TRUTH_SPEC)), model_digest="m")
    assert "truth_key" not in plain.table().column_names and all(j.truth_key is None for j in plain.jobs)
    assert [j.render_key for j in plain.jobs] == [j.render_key for j in truth.jobs]
    assert [j.pred_key for j in plain.jobs] == [j.pred_key for j in truth.jobs]
    keys = [j.truth_key for j in truth.jobs]
    assert len(set(keys)) == len(keys) and not set(keys) & {j.render_key for j in truth.jobs}
    table = truth.table()
    assert table.column("truth_key").null_count == 0 and b"sweep3d.min_visible" in table.schema.metadata
    assert [r["truth_key"] for r in truth.rows() if r["in_frame"]] == keys  # rows and columns agree
    assert len(truth.out_of_frame) == 2  # x = 2.5: the planner's geometric pre-check


def test_ground_truth_numbers_and_blobs_round_trip() -> None:
    mask = np.zeros((6, 8), dtype=bool)
    mask[2:4, 3:7] = True
    assert box(mask) == (3, 2, 7, 4)  # x1, y1 exclusive
    row = ground_truth(mask, 16.0)
    assert row["visible_pixels"] == 8 and row["visible_fraction"] == 0.5 and row["gt_x1"] == 7
    assert ground_truth(np.zeros((2, 2), bool), 10.0)["gt_x0"] is None
    assert ground_truth(mask, None)["visible_fraction"] is None
    assert (decode_mask(encode_mask(mask)) == mask).all()
    depth = np.array([[1.5, np.inf], [2.25, 3.0]], dtype=np.float32)
    assert np.array_equal(decode_depth(encode_depth(depth)), depth)


# -- real renders --------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def truth_run(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("truth_run")
    run_cli(write_spec(folder, TRUTH_SPEC))
    return folder


def truths(folder: Path) -> dict[tuple[float, float], dict]:
    """(x, coverage) → the job's row of ``ground_truth`` with its jobs columns."""
    con = connect_results(Store(folder / "store"), "truth")
    cursor = con.execute("SELECT j.position_x, j.occlusion_coverage, j.in_frame, g.* FROM jobs j "
                         "JOIN ground_truth g USING (job)")
    names = [d[0] for d in cursor.description]
    return {(r[0], r[1]): dict(zip(names, r)) for r in cursor.fetchall()}


def test_the_true_box_follows_the_object_and_is_the_masks_box(truth_run: Path) -> None:
    rows = truths(truth_run)
    store = Store(truth_run / "store")
    centre, right = rows[0.0, 0.0], rows[0.5, 0.0]
    assert centre["visible_fraction"] == pytest.approx(1.0, abs=0.02) and centre["evaluable"]
    assert right["gt_x0"] > centre["gt_x0"] + SIDE / 8 and (right["gt_x0"] + right["gt_x1"]) / 2 > SIDE * 0.6
    assert right["gt_x0"] >= SIDE / 2 - 2  # the box lies in the right half
    for row in rows.values():
        if row["truth_key"] is None or not row["in_frame"]:
            continue
        mask = decode_mask(store.blob_path(row["truth_key"], "mask.png").read_bytes())
        depth = decode_depth(store.blob_path(row["truth_key"], "depth.npz").read_bytes())
        assert mask.shape == depth.shape == (SIDE, SIDE)
        assert box(mask) == (None if row["gt_x0"] is None else (row["gt_x0"], row["gt_y0"], row["gt_x1"], row["gt_y1"]))
        assert int(mask.sum()) == row["visible_pixels"]
        assert np.isfinite(depth[mask]).all() and (depth[mask] > 0).all()
    # the digests recorded in the rows are the blobs'
    from sweep3d.cache.maintenance import verify

    assert verify(truth_run / "store").ok


def test_half_occluded_shows_half_and_out_of_frame_is_not_evaluable(truth_run: Path) -> None:
    rows = truths(truth_run)
    assert rows[0.0, 0.5]["visible_fraction"] == pytest.approx(0.5, abs=0.1)
    assert rows[0.0, 0.5]["evaluable"]  # 0.5 ≥ min_visible
    sliver = rows[1.6, 0.0]  # in frame for the geometric pre-check, a sliver in the image
    assert sliver["in_frame"] and sliver["visible_fraction"] < 0.1 and sliver["evaluable"] is False
    gone = rows[2.5, 0.0]
    assert not gone["in_frame"] and gone["evaluable"] is False and gone["visible_pixels"] is None
    con = connect_results(Store(truth_run / "store"), "truth")
    evaluable = con.execute("SELECT count(*) FILTER (WHERE evaluable), count(*) FROM results").fetchone()
    assert evaluable[1] == 6 and 3 <= evaluable[0] <= 5


def test_a_missing_truth_blob_renders_the_pass_again_and_nothing_else(truth_run: Path, tmp_path: Path) -> None:
    import shutil

    folder = tmp_path / "copy"
    shutil.copytree(truth_run, folder)
    store = Store(folder / "store")
    key = connect_results(store, "truth").execute("SELECT truth_key FROM truths LIMIT 1").fetchone()[0]
    store.blob_path(key, "mask.png").unlink()
    assert stage_counts(folder / "spec.toml") == {"render": 1, "infer": 0}
    assert store.blob_path(key, "mask.png").exists()
    assert stage_counts(folder / "spec.toml") == {"render": 0, "infer": 0}


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.torch
def test_switching_passes_on_renders_for_the_passes_only(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, PLAIN_SPEC)
    run_cli(spec)
    store = Store(tmp_path / "store")
    con = connect_results(store, "truth")
    before = dict(con.execute("SELECT render_key, sha256 FROM renders").fetchall())
    blobs = {key: store.blob_path(key).read_bytes() for key in before}
    # a run that needs no pass renders none: no truth rows, no truth blobs, workers without passes
    from sweep3d.stages.render.render_stage import render_settings

    assert not store.keys("truths") and not list((tmp_path / "store" / "blobs").glob("*/*.mask.png"))
    assert render_settings(plan_for(load_spec(spec))).passes == ()
    assert con.execute("SELECT bool_and(evaluable), count(*) FROM results").fetchone() == (True, 6)
    spec.write_text(TRUTH_SPEC)
    assert stage_counts(spec) == {"render": 6, "infer": 0}  # rendered for the passes; nothing re-inferred
    con = connect_results(store, "truth")
    assert dict(con.execute("SELECT render_key, sha256 FROM renders").fetchall()) == before
    assert {key: store.blob_path(key).read_bytes() for key in before} == blobs  # RGB blobs byte-identical
    assert con.execute("SELECT count(*) FROM truths").fetchone()[0] == 6
    assert con.execute("SELECT count(*) FROM results WHERE visible_fraction IS NULL").fetchone()[0] == 0


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.torch
def test_model_framing_gives_passes_in_the_stored_images_grid(tmp_path: Path) -> None:
    body = (TRUTH_SPEC.replace(f"resolution = {SIDE}", 'resolution = "model"')
            .replace("x = [0.0, 0.5, 1.6, 2.5]", "x = 0.3").replace("coverage = [0.0, 0.5]", "coverage = 0.0"))
    run_cli(write_spec(tmp_path, body))
    store = Store(tmp_path / "store")
    row = connect_results(store, "truth").execute("SELECT r.render_key, t.* FROM results r JOIN truths t USING (truth_key)")
    names = [d[0] for d in row.description]
    row = dict(zip(names, row.fetchone()))
    from sweep3d.core.pixels import decode_png

    image = decode_png(store.blob_path(row["render_key"]))
    mask = decode_mask(store.blob_path(row["truth_key"], "mask.png").read_bytes())
    assert mask.shape == image.shape[:2] == (224, 224)
    assert box(mask) == (row["gt_x0"], row["gt_y0"], row["gt_x1"], row["gt_y1"])
    assert (row["gt_x0"] + row["gt_x1"]) / 2 > 112 + 20 and row["visible_fraction"] == pytest.approx(1.0, abs=0.05)
    # the mask is in the image's grid: the object's pixels are the ones that differ from the white background
    differs = np.abs(image - 1.0).max(axis=-1) > 0.02
    assert (differs[mask]).mean() > 0.97 and (~differs[~mask]).mean() > 0.99


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.torch
def test_a_killed_run_resumes_its_truth_passes(tmp_path: Path) -> None:
    import os
    import signal
    import subprocess
    import sys
    import time

    from sweep3d.cache.maintenance import verify
    from tests.helpers import REPO

    body = TRUTH_SPEC.replace("x = [0.0, 0.5, 1.6, 2.5]", "x = { range = [-0.6, 0.6] }").replace(
        '[policy]\ntype = "grid"', '[policy]\ntype = "grid"\nsamples_per_dim = 12').replace(
        "samples = 1", "samples = 192")  # 24 renders, slow enough that the first segment (3 s) holds only some
    spec = write_spec(tmp_path, body)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen([sys.executable, "-m", "sweep3d", "run", str(spec), "--no-report"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    segments = tmp_path / "store" / "tables" / "truths"
    deadline = time.monotonic() + 300
    while proc.poll() is None and time.monotonic() < deadline and not list(segments.glob("*.parquet")):
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)  # mid-run: some renders and their truths recorded, not all
    proc.wait()
    store = Store(tmp_path / "store")
    done = store.keys("truths")
    assert 0 < len(done) < 24, f"the kill landed with {len(done)} of 24 truth rows recorded"
    assert store.keys("renders") and verify(tmp_path / "store").ok
    run_cli(spec)
    con = connect_results(store, "truth")
    assert con.execute("SELECT count(*), count(DISTINCT truth_key) FROM truths").fetchone() == (24, 24)
    assert con.execute("SELECT count(*) FROM results WHERE visible_fraction IS NULL").fetchone()[0] == 0
    assert verify(tmp_path / "store").ok
    assert stage_counts(spec) == {"render": 0, "infer": 0}


def _uv_sphere(rings: int = 32, segments: int = 64) -> str:
    """A unit UV sphere as OBJ text."""
    import math

    vertices = [(math.sin(math.pi * i / rings) * math.cos(2 * math.pi * j / segments), math.cos(math.pi * i / rings),
                 math.sin(math.pi * i / rings) * math.sin(2 * math.pi * j / segments))
                for i in range(rings + 1) for j in range(segments)]
    faces = [(i * segments + j, i * segments + (j + 1) % segments, (i + 1) * segments + (j + 1) % segments,
              (i + 1) * segments + j) for i in range(rings) for j in range(segments)]
    return "".join(f"v {x} {y} {z}\n" for x, y, z in vertices) + "".join(
        "f " + " ".join(str(k + 1) for k in face) + "\n" for face in faces)


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.torch
def test_zoom_frames_the_bounding_sphere_as_the_readme_says(tmp_path: Path) -> None:
    import math

    (tmp_path / "sphere.obj").write_text(_uv_sphere())
    side = 100
    spec = write_spec(tmp_path, TRUTH_SPEC.replace("cube.obj", "sphere.obj").replace(f"resolution = {SIDE}",
                      f"resolution = {side}").split("[[controls]]")[0]
                      + '[[controls]]\ntype = "camera"\nzoom = [0.5, 1.0]\nelevation = 0\n\n[policy]\ntype = "grid"\n'
                      + '\n[evaluator]\npasses = ["mask"]\n', cube=False)
    run_cli(spec)
    half = math.atan(18 / 50)
    spans = connect_results(Store(tmp_path / "store"), "truth").execute(
        "SELECT camera_zoom, gt_x1 - gt_x0, gt_y1 - gt_y0 FROM results ORDER BY 1").fetchall()
    assert len(spans) == 2
    for zoom, width, height in spans:
        expected = math.tan(math.asin(0.8 * zoom * math.sin(half))) / math.tan(half) * side
        assert abs(width - expected) <= 2 and abs(height - expected) <= 2, (zoom, width, expected)


def test_adaptive_search_does_not_count_a_hidden_object_as_a_failure(truth_run: Path) -> None:
    from sweep3d.runner.pipeline import outcomes_by_scene

    spec = load_spec(truth_run / "spec.toml")
    plan = plan_for(spec)
    history = outcomes_by_scene(plan, Store(truth_run / "store"))
    con = connect_results(Store(truth_run / "store"), "truth")
    rows = dict(con.execute("SELECT truth_key, visible_fraction FROM truths").fetchall())
    wrong = dict(con.execute("SELECT pred_key, valid AND NOT correct FROM predictions").fetchall())
    for job in plan.jobs:
        outcome = history[job.scene][job.point]
        if (rows[job.truth_key] or 0) < spec.evaluator.min_visible:  # the sliver at x = 1.6
            assert not outcome.failed and outcome.loss == 0.0
        else:
            assert outcome.failed == wrong[job.pred_key]
    assert any((rows[j.truth_key] or 0) < spec.evaluator.min_visible for j in plan.jobs)
