"""`sweep3d bench`: scene-load time reported apart from steady-state render time, and `--budget`.

Most tests here need neither Blender nor torch (the parsing of Blender's progress, the split of
times, the job count a budget buys); the ones marked ``blender`` start real render workers at
32×32 pixels and a few samples. The command line's refusals are in tests/cli/test_bad_input.py.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.bench.budget import bench_seconds, budget_chooser, choose_jobs
from sweep3d.bench.measurement import ROUNDS, Setting, default_settings, reference_settings, split_times
from sweep3d.cli import app
from sweep3d.core.errors import UserError
from sweep3d.stages.render.render_log import parse_setup_seconds
from sweep3d.stages.render.worker_protocol import RenderInfo
from tests.helpers import TINY_SPEC, load_spec, plan_for, write_spec

runner = CliRunner()

#: What Blender 4.5 prints to fd 1 during a render (abridged): the Time: of "Sample 0/N" is
#: Cycles' set-up of the render, the importance map here.
BLENDER_LINES = """\
Fra:1 Mem:8.64M (Peak 16.35M) | Time:00:00.04 | Mem:8.08M, Peak:8.08M | Scene, ViewLayer | Updating Lights | Importance map
Fra:1 Mem:80.68M (Peak 368.65M) | Time:00:03.37 | Mem:72.13M, Peak:232.10M | Scene, ViewLayer | Updating Integrator
Fra:1 Mem:80.69M (Peak 368.65M) | Time:00:03.37 | Mem:72.13M, Peak:232.10M | Scene, ViewLayer | Sample 0/4
Fra:1 Mem:80.77M (Peak 368.65M) | Time:00:03.39 | Remaining:00:00.00 | Mem:72.19M | Scene, ViewLayer | Sample 1/4
Fra:1 Mem:80.83M (Peak 368.65M) | Time:00:03.41 | Mem:72.19M, Peak:232.10M | Scene, ViewLayer | Finished
"""

#: One scene with 48 distinct renders (yaw), so a budget has jobs to choose from.
MANY_YAWS = TINY_SPEC.replace('yaw = [0, 45]', 'yaw = [' + ", ".join(str(7 * i) for i in range(48)) + ']') \
    .replace('[[environments]]\nname = "studio"\nhdri = "builtin:studio"\n', "")


def test_blender_progress_gives_the_set_up_before_the_first_sample() -> None:
    assert parse_setup_seconds(BLENDER_LINES) == pytest.approx(3.37)
    assert parse_setup_seconds("| Time:01:02:03.50 | Scene, ViewLayer | Sample 0/512") == pytest.approx(3723.5)
    stale = "| Time:00:09.00 | Sample 0/4\nSaved: 'frame.png'\n"  # a previous render's line left over
    assert parse_setup_seconds(stale + BLENDER_LINES) == pytest.approx(3.37)  # the latest render's
    assert parse_setup_seconds("Saved: 'frame.png'\nTime: 00:00.02 (Saving: 00:00.00)\n") is None


def test_steady_time_leaves_scene_loads_out_and_loads_are_reported_apart() -> None:
    timings = {"a": RenderInfo(seconds=3.5, valid=True, width=8, height=8, load_seconds=3.0),
               "b": RenderInfo(seconds=0.5, valid=True, width=8, height=8),
               "c": RenderInfo(seconds=0.7, valid=True, width=8, height=8)}
    times = split_times(["a", "b", "c"], timings, stored={"a": 3.5, "b": 0.5, "c": 0.7})
    assert times["seconds"] == pytest.approx(0.5)  # median of 0.5, 0.5, 0.7: not 0.7 with the load
    assert times["load_seconds"] == pytest.approx(3.0) and times["loads"] == 1 and times["timed"] == 3
    assert times["render_total"] == pytest.approx(1.7)
    cached = split_times(["a", "b"], {}, stored={"a": 3.5, "b": 0.5})  # nothing rendered in this run
    assert cached["seconds"] == pytest.approx(2.0) and cached["load_seconds"] is None and cached["timed"] == 0


def test_a_smaller_budget_picks_fewer_jobs() -> None:
    costs = [2.0, 2.0, 0.3, 0.1]  # seconds per render: reference, floor, two settings
    chosen = [choose_jobs(minutes, costs, scenes=20, available=500, rounds=ROUNDS).jobs for minutes in (3, 10, 30)]
    assert chosen[0] < chosen[1] < chosen[2] < 500
    for minutes, jobs in zip((3, 10, 30), chosen):  # the most that fit: one more would not
        assert bench_seconds(jobs, costs, 20, ROUNDS) <= minutes * 60 < bench_seconds(jobs + 1, costs, 20, ROUNDS)
    choice = choose_jobs(600, costs, scenes=20, available=40, rounds=ROUNDS)
    assert choice.jobs == 40 and "every distinct render" in choice.line()  # capped by what the spec plans
    with pytest.raises(UserError, match="too short"):
        choose_jobs(0.1, costs, scenes=20, available=500, rounds=ROUNDS)


def test_budget_chooses_from_the_specs_plan_and_its_settings(tmp_path: Path) -> None:
    loaded = load_spec(write_spec(tmp_path, MANY_YAWS))
    plan = plan_for(loaded, "stand-in")
    current = Setting(1, "off", 8)
    reference, floor = reference_settings(64, "off", current, model_view=False)
    settings = [reference, floor] + default_settings(current, model_view=False)
    said = []
    picks = [budget_chooser(loaded, settings, minutes, said.append)(plan) for minutes in (4, 8, 60)]
    assert picks[0] < picks[1] < picks[2] == 48  # an hour buys every distinct render of the spec
    assert [c.jobs for c in said] == picks
    assert all(line.count("\n") == 0 and line.startswith(f"--budget {m} min: {n} job")
               for line, m, n in zip((c.line() for c in said), (4, 8, 60), picks))


@pytest.mark.blender
def test_a_worker_reports_scene_loads_apart_from_steady_renders(tmp_path: Path) -> None:
    """The first job (mesh import, first render) and a switch to an HDRI world (its importance
    map) report a load; a job in the scene already shown reports none."""
    from sweep3d.assets.sources import builtin_hdris
    from sweep3d.stages.render.controls import Orientation
    from sweep3d.stages.render.pool import RenderPool
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderJob, RenderSettings
    from tests.helpers import write_cube

    cube = str(write_cube(tmp_path))
    white, studio = EnvironmentRef(color=(1.0, 1.0, 1.0)), EnvironmentRef(hdri=str(builtin_hdris()["studio"]))
    turn = ((Orientation("orientation", "orientation"), Orientation.Params(yaw=30.0)),)
    groups = [[RenderJob("first", cube, white), RenderJob("posed", cube, white, turn)],
              [RenderJob("hdri", cube, studio), RenderJob("hdri posed", cube, studio, turn)]]
    with RenderPool(RenderSettings(resolution=32, samples=2, denoise=False), workers=1, timeout=120) as pool:
        info = {reply.render_key: reply.info for reply in pool.run(groups)}
    assert info["first"].load_seconds > 0 and info["hdri"].load_seconds > 0
    assert info["posed"].load_seconds == 0 and info["hdri posed"].load_seconds == 0
    assert all(0 <= i.load_seconds <= i.seconds for i in info.values())
    # Cycles' importance map, read off Blender's progress, is most of the switch: far more than a render
    assert info["hdri"].load_seconds > 5 * info["hdri posed"].render_seconds


@pytest.mark.blender
@pytest.mark.torch
@pytest.mark.slow
def test_bench_reports_load_apart_and_runs_the_jobs_its_budget_chose(tmp_path: Path, monkeypatch) -> None:
    """A whole bench (about 3 min on 2 cores: every setting's pass starts a worker)."""
    import importlib

    from rich.console import Console

    monkeypatch.setattr(importlib.import_module("sweep3d.cli.app"), "console", Console(width=250))  # rows unwrapped
    spec = write_spec(tmp_path, MANY_YAWS)
    result = runner.invoke(app, ["bench", str(spec), "--budget", "4", "--no-floor", "--reference-samples", "4",
                                 "--agreement", "0.5"])
    assert result.exit_code == 0, result.output
    chose = re.search(r"--budget 4 min: (\d+) jobs?,", result.output)
    assert chose, result.output
    jobs = int(chose.group(1))
    assert 1 <= jobs < 48 and f"{jobs} jobs. top-1" in result.output  # the table covers what was chosen
    rows = [line for line in result.output.splitlines() if line.startswith("│") and "spp" in line]
    loads = [re.search(r"│\s*(\d+(?:\.\d+)?(?:e-\d+)?) ×(\d+)\s*│", row) for row in rows]
    assert rows and all(loads), result.output  # every setting was rendered here, each pass by a new worker
    assert all(float(m.group(1)) > 0 and int(m.group(2)) >= 1 for m in loads)
    assert re.search(r"scene loads: \d+ of \d+ renders in this run switched scene first", result.output)
    assert "the bench took" in result.output


def test_another_engine_is_measured_beside_the_grid_but_never_recommended() -> None:
    from sweep3d.bench.measurement import BenchRow, recommend

    current = Setting(4, "fast", resolution="model")
    settings = default_settings(current, True, 256, ["mitsuba", "cycles"])
    others = [s for s in settings if s.engine != "cycles"]
    assert others == [Setting(4, "fast", resolution="model", engine="mitsuba")]  # the spec's setting, once
    assert others[0].label() == "mitsuba 4spp oidn-fast model" and others[0].render_update(256)["engine"] == "mitsuba"
    rows = [BenchRow(current, 1.0, 40.0, 0.99, 100, 100, 100),
            BenchRow(others[0], 0.5, 30.0, 0.9, 100, 100, 100)]  # faster, agrees as well: still not chosen
    assert recommend(rows, 0.99) is rows[0] and rows[1].passes
    assert recommend(rows, 0.99, engine="mitsuba") is rows[1]  # a Mitsuba spec's bench tunes Mitsuba


def test_a_mitsuba_specs_bench_renders_its_grid_and_reference_with_mitsuba() -> None:
    """A second renderer is judged by its own converged image: the reference, its noise floor and
    the grid are Mitsuba's, without the Cycles-only adaptive sampling; Cycles is a row of its own."""
    current = Setting(4, "fast", resolution="model", engine="mitsuba")
    reference, floor = reference_settings(512, "off", current, model_view=True)
    assert reference.engine == floor.engine == "mitsuba" and floor.seed != reference.seed
    settings = default_settings(current, True, 256, ["cycles"])
    cycles = [s for s in settings if s.engine == "cycles"]
    assert cycles == [Setting(4, "fast", resolution="model")]  # the spec's setting, once
    mitsuba = [s for s in settings if s.engine == "mitsuba"]
    assert current in mitsuba and not any(s.adaptive for s in mitsuba)
    assert {s.samples for s in mitsuba} >= {1, 4, 16} and len(mitsuba) == len(settings) - 1
    cycles_grid = default_settings(Setting(4, "fast", resolution="model"), True, 256)
    assert any(s.adaptive for s in cycles_grid) and len(cycles_grid) == len(mitsuba) + 1  # the same grid, and adaptive
    assert reference_settings(512, "off", Setting(4, "fast"), model_view=True)[0].engine == "cycles"


def test_an_unknown_engine_is_one_line_and_exit_code_2(tmp_path: Path) -> None:
    result = CliRunner().invoke(app, ["bench", str(write_spec(tmp_path, TINY_SPEC)), "--engine", "luxcore"])
    assert result.exit_code == 2 and "--engine 'luxcore': use one of cycles, mitsuba" in result.output
    assert len(result.output.strip().splitlines()) == 1
