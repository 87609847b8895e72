"""End to end through the CLI with real Blender renders and the real model: what each rerun recomputes."""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.results import connect as connect_results
from sweep3d.runner.pipeline import run
from tests.helpers import REPO, TINY_SPEC, load_spec, write_cube, write_spec

pytestmark = pytest.mark.slow

TEST_MODEL = '''
import torch

def make():
    torch.manual_seed(0)
    return torch.nn.Sequential(
        torch.nn.Conv2d(3, 4, 3, stride=4), torch.nn.ReLU(),
        torch.nn.AdaptiveAvgPool2d(1), torch.nn.Flatten(), torch.nn.Linear(4, 1000))
'''


def computed(folder: Path) -> dict[str, int]:
    """Run the folder's spec in-process and return how many keys each stage computed."""
    result = run(load_spec(folder / "spec.toml"))
    assert result.failed == 0
    return {o.stage: o.computed for o in result.outcomes}


def edit_spec(folder: Path, old: str, new: str) -> None:
    path = folder / "spec.toml"
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


def test_first_run_stores_every_stage(tiny_run: Path) -> None:
    store = Store(tiny_run / "store")
    assert len(store.keys("renders")) == 4  # 2 yaws × 2 environments
    assert len(store.keys("images")) == 4  # the blurred variants (sigma 0 reuses the render)
    assert len(store.keys("predictions")) == 8
    con = connect_results(store, "tiny")
    assert con.execute("SELECT count(*) FROM results").fetchone()[0] == 8
    nulls = con.execute("SELECT count(*) FROM results WHERE valid AND (loss IS NULL OR isnan(loss))").fetchone()[0]
    assert nulls == 0


def test_second_run_computes_nothing(tiny_copy: Path) -> None:
    started = time.perf_counter()
    assert computed(tiny_copy) == {"render": 0, "postprocess": 0, "infer": 0}
    assert time.perf_counter() - started < 10


def test_changing_a_post_value_renders_nothing(tiny_copy: Path) -> None:
    edit_spec(tiny_copy, "sigma = [0.0, 1.5]", "sigma = [0.0, 2.5]")
    assert computed(tiny_copy) == {"render": 0, "postprocess": 4, "infer": 4}


def test_changing_the_model_renders_and_postprocesses_nothing(tiny_copy: Path, monkeypatch) -> None:
    (tiny_copy / "tiny_test_model.py").write_text(TEST_MODEL)
    monkeypatch.syspath_prepend(str(tiny_copy))
    edit_spec(tiny_copy, "[model]\n", '[model]\nname = "tiny_test_model:make"\n')
    assert computed(tiny_copy) == {"render": 0, "postprocess": 0, "infer": 8}
    con = connect_results(Store(tiny_copy / "store"), "tiny")
    models = {r[0] for r in con.execute("SELECT model FROM results").fetchall()}
    assert models == {"tiny_test_model:make"}


def test_adding_an_object_renders_only_its_scenes(tiny_copy: Path) -> None:
    (tiny_copy / "cube2.obj").write_text((tiny_copy / "cube.obj").read_text().replace("v 1 1 1", "v 1.5 1 1"))
    edit_spec(tiny_copy, "[[environments]]", '[[objects]]\nname = "box2"\nmesh = "cube2.obj"\nlabels = ["carton"]\n\n[[environments]]', )
    assert computed(tiny_copy) == {"render": 4, "postprocess": 4, "infer": 8}


def test_blender_starts_while_the_model_is_checked_and_a_broken_model_leaves_no_worker(tiny_copy, monkeypatch) -> None:
    from sweep3d.core.errors import UserError
    from sweep3d.stages.infer import InferStage
    from sweep3d.stages.render.child import live_children
    from sweep3d.stages.render.pool import RenderPool

    edit_spec(tiny_copy, "yaw = [0, 45]", "yaw = [10, 55]")  # renders to make
    starts: list[int] = []
    real_start = RenderPool._start
    monkeypatch.setattr(RenderPool, "_start", lambda pool, slot: starts.append(slot) or real_start(pool, slot))
    check = InferStage.prepare

    def broken(stage, plan, store):
        assert starts == [0], "the first worker is starting before the model's check"
        raise UserError("model.name: the model is broken")

    monkeypatch.setattr(InferStage, "prepare", broken)
    with pytest.raises(UserError, match="broken"):
        run(load_spec(tiny_copy / "spec.toml"))
    assert live_children() == [], "the worker started ahead is stopped"
    monkeypatch.setattr(InferStage, "prepare", check)
    starts.clear()
    assert computed(tiny_copy) == {"render": 4, "postprocess": 4, "infer": 8}
    assert starts == [0], "the worker started ahead renders: no second one"


def test_the_command_line_renders_with_the_worker_it_started_before_reading_the_spec(tiny_copy, monkeypatch) -> None:
    from sweep3d.stages.render import pool
    from sweep3d.stages.render.child import live_children

    edit_spec(tiny_copy, "yaw = [0, 45]", "yaw = [10, 55]")  # renders to make
    spawned: list[tuple] = []
    real_child = pool.Child
    monkeypatch.setattr(pool, "Child", lambda *args, **kwargs: spawned.append(args) or real_child(*args, **kwargs))
    result = CliRunner().invoke(app, ["run", str(tiny_copy / "spec.toml"), "--no-report"])
    assert result.exit_code == 0, result.output
    assert re.search(r"render\s*│\s*4\s*│\s*0\s*│\s*4\s*│", result.output), result.output  # needed, cached, computed
    assert spawned == [], "the pool took the worker started ahead instead of starting one"
    assert live_children() == []
    result = CliRunner().invoke(app, ["run", str(tiny_copy / "spec.toml"), "--no-report"])  # nothing to render
    assert result.exit_code == 0, result.output
    assert live_children() == [], "the worker started ahead is ended when nothing takes it"


def test_cli_run_prints_stage_counts_and_writes_report(tiny_copy: Path) -> None:
    result = CliRunner().invoke(app, ["run", str(tiny_copy / "spec.toml")])
    assert result.exit_code == 0, result.output
    assert "render" in result.output and "infer" in result.output
    assert "report:" in result.output
    assert (tiny_copy / "store" / "reports" / "tiny.html").is_file()


def test_cli_plan_reports_cached_keys(tiny_copy: Path) -> None:
    result = CliRunner().invoke(app, ["plan", str(tiny_copy / "spec.toml")])
    assert result.exit_code == 0, result.output
    assert "8 jobs" in result.output
    lines = {line.split("│")[1].strip(): line for line in result.output.splitlines() if line.count("│") > 3}
    assert "│ 4      │ 4      │ 0 " in lines["render"]
    assert "│ 8      │ 8      │ 0 " in lines["infer"]


def test_sheet_shows_one_row_per_control(tiny_copy: Path) -> None:
    from PIL import Image

    from sweep3d.report.sheet import LABEL_WIDTH, TILE

    edit_spec(tiny_copy, "[policy]", '[[controls]]\ntype = "material"\nskin = ["original", "zebra", "cow"]\n\n[policy]')
    out = tiny_copy / "sheet.png"
    result = CliRunner().invoke(app, ["sheet", str(tiny_copy / "spec.toml"), "-o", str(out)])
    assert result.exit_code == 0, result.output
    with Image.open(out) as sheet:
        assert sheet.size == (LABEL_WIDTH + 3 * TILE, 3 * TILE)  # 3 controls; at most 3 values each
        pixels = np.asarray(sheet.convert("RGB"), dtype=np.float32)
    tiles = [pixels[2 * TILE : 3 * TILE - 14, LABEL_WIDTH + i * TILE : LABEL_WIDTH + (i + 1) * TILE] for i in range(3)]
    assert np.abs(tiles[0] - tiles[1]).mean() > 1 and np.abs(tiles[1] - tiles[2]).mean() > 1  # skins differ
    assert "white" in result.output and "shown" not in result.output  # the spec's first scene, nothing sampled

    # another base view, and fewer tiles than values: said, one line per sampled row
    result = CliRunner().invoke(app, ["sheet", str(tiny_copy / "spec.toml"), "-o", str(out), "--environment",
                                      "studio", "--tiles", "2"])
    assert result.exit_code == 0, result.output
    assert "box in studio" in result.output
    assert result.output.count("values shown") == 1 and "2 of its 3 values shown, evenly spread" in result.output
    with Image.open(out) as sheet:
        assert sheet.size == (LABEL_WIDTH + 2 * TILE, 3 * TILE)
        studio = np.asarray(sheet.convert("RGB"), dtype=np.float32)
    assert np.abs(studio[:TILE, LABEL_WIDTH:LABEL_WIDTH + TILE] - pixels[:TILE, LABEL_WIDTH:LABEL_WIDTH + TILE]).mean() > 1
    result = CliRunner().invoke(app, ["sheet", str(tiny_copy / "spec.toml"), "--object", "mug"])
    assert result.exit_code == 2 and "no object named 'mug' for --object; the spec has 'box'" in result.output


ADAPTIVE_SPEC = TINY_SPEC.replace("yaw = [0, 45]", "yaw = { range = [-180, 180] }\npitch = { range = [-90, 90] }").replace(
    'sigma = [0.0, 1.5]', 'sigma = { range = [0.0, 3.0] }').replace(
    '[policy]\ntype = "grid"', '[policy]\ntype = "adaptive"\nsamples = 12\ninitial = 4\nbatch = 4')


def test_adaptive_policy_runs_rounds_and_resumes_from_the_cache(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, ADAPTIVE_SPEC)
    first = run(load_spec(spec))
    assert first.failed == 0
    assert len(first.plan.jobs) == 24  # 12 per scene, proposed over 3 rounds
    assert first.outcome("render").computed == 24
    again = run(load_spec(spec))  # replays the rounds: every key is cached, same jobs
    assert again.outcome("render").computed == 0 and again.outcome("infer").computed == 0
    assert [j.pred_key for j in again.plan.jobs] == [j.pred_key for j in first.plan.jobs]
    rows = connect_results(Store(tmp_path / "store"), "tiny").execute("SELECT count(*) FROM results").fetchone()[0]
    assert rows == 24


def test_the_all_controls_spec_renders_every_control_without_error(tmp_path: Path) -> None:
    from sweep3d.runner import builtin_catalogue as catalogue

    CONTROLS = catalogue().controls

    text = (REPO / "specs" / "all_controls.toml").read_text()
    listed = set(re.findall(r"^type\s*=\s*\"(\w+)\"", text.split("[policy]")[0], re.M))
    assert listed == set(CONTROLS.names()), "specs/all_controls.toml must use every built-in control"
    text = (text.replace("resolution = 224", "resolution = 32").replace("samples    = 4", "samples    = 1")
            .replace('store = "../.sweep3d"', 'store = "store"').replace("samples = 64", "samples = 12"))
    spec = tmp_path / "all.toml"
    write_cube(tmp_path)
    spec.write_text(re.sub(r'mesh\s*=\s*".*"', 'mesh = "cube.obj"', text))
    result = run(load_spec(spec))
    assert result.failed == 0, [e for o in result.outcomes for e in o.errors]
    assert result.outcome("render").computed == 12 and result.outcome("infer").computed == 12


def test_onnx_backend_reinfers_but_renders_nothing_and_agrees(tiny_copy: Path) -> None:
    con = connect_results(Store(tiny_copy / "store"), "tiny")
    torch_rows = con.execute("SELECT job, top1_label, correct FROM results ORDER BY job").fetchall()
    edit_spec(tiny_copy, "[model]\n", '[model]\nbackend = "onnx"\n')
    assert computed(tiny_copy) == {"render": 0, "postprocess": 0, "infer": 8}
    con = connect_results(Store(tiny_copy / "store"), "tiny")
    assert con.execute("SELECT job, top1_label, correct FROM results ORDER BY job").fetchall() == torch_rows


RESULT_COLUMNS = "SELECT job, render_key, image_key, pred_key, top1_label, correct FROM results ORDER BY job"
ANSWERS = "SELECT job, image_key, top1_label, correct, topk_labels FROM results ORDER BY job"


def test_torch_infers_under_keys_of_its_own_with_the_stand_in_s_answers(tiny_copy: Path) -> None:
    """tiny_copy was inferred by ONNX Runtime standing in for torch (the default). Eager torch
    gives the same ranks but probabilities apart in the last digits, so it finds none of the
    stand-in's predictions cached: it infers every job under keys of its own (and renders
    nothing), and the default finds its own again."""
    stand_in = connect_results(Store(tiny_copy / "store"), "tiny").execute(ANSWERS).fetchall()
    default_keys = connect_results(Store(tiny_copy / "store"), "tiny").execute(RESULT_COLUMNS).fetchall()
    edit_spec(tiny_copy, "[model]\n", '[model]\nbackend = "torch"\n')
    assert computed(tiny_copy) == {"render": 0, "postprocess": 0, "infer": 8}
    con = connect_results(Store(tiny_copy / "store"), "tiny")
    assert con.execute(ANSWERS).fetchall() == stand_in
    assert not {r[3] for r in con.execute(RESULT_COLUMNS).fetchall()} & {r[3] for r in default_keys}
    edit_spec(tiny_copy, '[model]\nbackend = "torch"\n', "[model]\n")
    assert computed(tiny_copy) == {"render": 0, "postprocess": 0, "infer": 0}


def test_overlapped_stages_give_what_stages_one_after_the_other_give(tmp_path: Path) -> None:
    results = {}
    for overlap in (True, False):
        folder = tmp_path / str(overlap)
        folder.mkdir()
        write_spec(folder, TINY_SPEC)
        result = run(load_spec(folder / "spec.toml"), overlap=overlap)
        counts = [(o.stage, o.total, o.cached, o.computed, o.failed, o.skipped) for o in result.outcomes]
        results[overlap] = (counts, connect_results(Store(folder / "store"), "tiny").execute(RESULT_COLUMNS).fetchall())
    assert results[True] == results[False]
    assert results[True][0] == [("render", 4, 0, 4, 0, 0), ("postprocess", 4, 0, 4, 0, 0), ("infer", 8, 0, 8, 0, 0)]


def test_bench_measures_settings_and_applies_the_recommendation(tiny_copy: Path) -> None:
    import tomllib

    spec = tiny_copy / "spec.toml"
    spec.write_text("# my experiment\n" + spec.read_text())
    # One job: every setting's pass starts a render worker (ROUNDS turns, one with the job), so a
    # second job would double the workers started and prove nothing more here (at --agreement 0.5 a
    # setting passes on one job as on two; tests/bench/test_bench.py runs a bench of several jobs).
    args = ["bench", str(spec), "--jobs", "1", "--reference-samples", "8", "--agreement", "0.5"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "recommended:" in result.output
    assert (tiny_copy / "store" / "reports" / "bench" / "tiny.html").stat().st_size > 100_000
    again = CliRunner().invoke(app, args + ["--apply"])
    assert again.exit_code == 0, again.output
    assert "failed" not in again.output  # every setting was cached: no progress bar ran
    text = spec.read_text()
    assert text.startswith("# my experiment")  # comments survive --apply
    render = tomllib.loads(text)["render"]
    assert set(render) >= {"samples", "denoise", "denoise_prefilter", "max_bounces", "resolution"}
    load_spec(spec)  # still a valid spec
