"""The Python API: an experiment from a path, a TOML string or a dict (with plug-in classes in it),
planned with the keys of the same spec as a file, and its results as a pyarrow Table, a pandas
DataFrame, SQL and a report, through the functions the command line calls."""

from __future__ import annotations

import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
from pydantic import Field

import sweep3d
from sweep3d.core.errors import SpecError, UserError
from sweep3d.plugins import ControlParams, Point, Policy, PostControl, RenderedControl
from tests.helpers import REPO, TINY_SPEC, plan_for, write_cube, write_spec

RESULTS = 40


def keys(experiment) -> list[tuple[str, str]]:
    return [(j.render_key, j.pred_key) for j in plan_for(experiment.spec, "m").jobs]


def test_importing_sweep3d_imports_neither_bpy_nor_torch_nor_pandas() -> None:
    code = ("import sys, sweep3d; sweep3d.Experiment; sweep3d.plugins.Policy; "
            "print(sorted(m for m in ('bpy', 'torch', 'pandas') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    assert out.stdout.strip() == "[]"


def test_a_dict_a_string_and_a_file_are_the_same_experiment(tmp_path: Path) -> None:
    write_cube(tmp_path)
    (tmp_path / "spec.toml").write_text(TINY_SPEC)
    from_file = sweep3d.load(tmp_path / "spec.toml")
    from_text = sweep3d.load(TINY_SPEC, base=tmp_path)
    from_dict = sweep3d.Experiment(tomllib.loads(TINY_SPEC), base=tmp_path)
    assert keys(from_file) == keys(from_text) == keys(from_dict) and len(keys(from_file)) == 8
    assert from_dict.store == from_file.store == (tmp_path / "store").resolve()
    assert str(from_dict.spec.path) == "<dict>" and "[[objects]]" in from_dict.spec.text()
    assert from_text.spec.text() == TINY_SPEC


def test_a_dicts_mistakes_are_one_line_spec_errors_naming_it(tmp_path: Path) -> None:
    spec = tomllib.loads(TINY_SPEC)
    with pytest.raises(SpecError, match=r"^<dict>: objects\[0\]\.mesh: .*cube\.obj") as caught:
        sweep3d.load(spec, base=tmp_path)  # no cube.obj there
    assert "\n" not in str(caught.value)
    spec["render"]["samples"] = "many"
    with pytest.raises(SpecError, match=r"^<dict>: render\.samples: "):
        sweep3d.load(spec, base=tmp_path)
    with pytest.raises(SpecError, match=r"^<string>: not valid TOML"):
        sweep3d.load("[experiment\nname = 1", base=tmp_path)
    with pytest.raises(UserError, match="a spec is a path, TOML text or a dict, got int"):
        sweep3d.load(3)


@pytest.mark.parametrize("where, tie", [
    ("x", lambda spec: spec.__setitem__("x", spec)),
    ("render.again", lambda spec: spec["render"].__setitem__("again", spec["render"])),
    (r"controls\[0\]\.yaw\[2\]", lambda spec: spec["controls"][0]["yaw"].append(spec["controls"][0]["yaw"])),
])
def test_a_dict_that_holds_itself_is_one_line_not_a_recursion_error(tmp_path: Path, where: str, tie) -> None:
    spec = tomllib.loads(TINY_SPEC)
    tie(spec)
    with pytest.raises(SpecError, match=rf"^<dict>: {where}: holds itself \(a dict or list that contains itself") as caught:
        sweep3d.load(spec, base=tmp_path)
    assert "\n" not in str(caught.value) and caught.value.exit_code == 2
    shared = tomllib.loads(TINY_SPEC)  # the same list in two places is no cycle
    write_cube(tmp_path)
    shared["environments"].append({"name": "white again", "color": shared["environments"][0]["color"]})
    assert len(sweep3d.load(shared, base=tmp_path).spec.environments) == 3


def test_a_dict_nested_too_deep_is_one_line(tmp_path: Path) -> None:
    spec = tomllib.loads(TINY_SPEC)
    deep: dict = {}
    spec["render"]["deep"] = deep
    for _ in range(5000):
        deep["d"] = {}
        deep = deep["d"]
    with pytest.raises(SpecError, match=r"^<dict>: render\.deep(\.d)+: nests more than 64 levels deep"):
        sweep3d.load(spec, base=tmp_path)


def test_a_dict_of_a_hundred_thousand_values_loads_and_is_refused_over_max_jobs_at_once(tmp_path: Path) -> None:
    write_cube(tmp_path)
    spec = tomllib.loads(TINY_SPEC)
    spec["controls"][0]["yaw"] = [i * 360 / 100_000 for i in range(100_000)]
    spec["controls"][1]["sigma"] = [i / 20 for i in range(40)]
    started = time.monotonic()
    experiment = sweep3d.load(spec, base=tmp_path)  # tomlkit's text took minutes, and the values' dedup too
    assert len(experiment.spec.controls[0].spaces["yaw"].values()) == 100_000
    with pytest.raises(SpecError, match=r"^<dict>: policy: the spec expands to 8,000,000 jobs, over the limit"):
        experiment.plan()
    assert time.monotonic() - started < 30  # seconds, on a loaded machine
    assert not (tmp_path / "store").exists()


class Darken(PostControl):
    """A post control of a notebook's: runs in this process, so it may live anywhere."""

    class Params(ControlParams):
        amount: float = Field(0.0, ge=0.0, le=1.0)

    def apply(self, image, params, rng):
        return (image * (1.0 - params.amount)).astype(np.float32)


class Corners(Policy):
    def points(self, shape, seed, history):
        return [Point((u,) * shape.n_continuous, (0,) * len(shape.choice_sizes)) for u in (0.0, 1.0)]

    def count(self, shape):
        return 2


def dict_spec(**changes) -> dict:
    spec = tomllib.loads(TINY_SPEC)
    spec.update(changes)
    return spec


def test_plug_in_classes_in_a_dict_are_used_as_named_in_a_file(tmp_path: Path) -> None:
    write_cube(tmp_path)
    spec = dict_spec(policy={"type": Corners})
    spec["controls"].append({"type": Darken, "amount": [0.0, 0.5]})
    experiment = sweep3d.load(spec, base=tmp_path)
    assert [c.control.type_name for c in experiment.spec.controls][-1] == "tests.api.test_api:Darken"
    assert len(experiment.plan().jobs) == 2 * 2  # two corner points per scene, two scenes
    # the same spec in a file names them by module: the same keys
    text = TINY_SPEC.replace('type = "grid"', 'type = "tests.api.test_api:Corners"').replace(
        "[policy]", '[[controls]]\ntype = "tests.api.test_api:Darken"\namount = [0.0, 0.5]\n\n[policy]')
    assert keys(experiment) == keys(sweep3d.load(text, base=tmp_path))


def test_a_rendered_control_from_main_or_a_function_is_refused_saying_how(tmp_path: Path) -> None:
    write_cube(tmp_path)

    class Lift(RenderedControl):
        class Params(ControlParams):
            height: float = 0.0

        def apply(self, state, params):
            pass

    spec = dict_spec()
    spec["controls"].append({"type": Lift, "height": [0.0, 1.0]})
    with pytest.raises(SpecError) as caught:
        sweep3d.load(spec, base=tmp_path)
    message = str(caught.value)
    assert message.startswith("<dict>: controls[2].type: rendered control Lift is defined in a function; ")
    assert 'put the class in a module file' in message and 'type = "mycontrols:Lift"' in message
    Lift.__module__, Lift.__qualname__ = "__main__", "Lift"  # as a notebook cell defines it
    with pytest.raises(SpecError, match=r"Lift is defined in __main__ \(a notebook cell or the script being run\)"):
        sweep3d.load(spec, base=tmp_path)


def test_a_rendered_control_from_main_is_refused_by_name_too(tmp_path: Path) -> None:
    """``type = "__main__:Name"`` in a file: the same refusal (the name imports here, not in a worker)."""
    script = tmp_path / "script.py"
    script.write_text(
        "import sys\nfrom sweep3d.plugins import RenderedControl\nimport sweep3d\n"
        "from sweep3d.core.errors import SpecError\n"
        "class Lift(RenderedControl):\n    def apply(self, state, params):\n        pass\n"
        "try:\n    sweep3d.load(sys.argv[1])\nexcept SpecError as exc:\n    print(exc)\n")
    spec = tmp_path / "spec.toml"
    write_cube(tmp_path)
    spec.write_text(TINY_SPEC.replace("[policy]", '[[controls]]\ntype = "__main__:Lift"\n\n[policy]'))
    out = subprocess.run([sys.executable, str(script), str(spec)], capture_output=True, text=True, cwd=REPO,
                         env={"PYTHONPATH": str(REPO)}, check=True)
    assert "controls[2].type: rendered control Lift is defined in __main__" in out.stdout, out.stdout + out.stderr


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory) -> Path:
    """A spec and its store holding synthetic results (no Blender, no model)."""
    from tests.helpers import build_store

    return build_store(tmp_path_factory.mktemp("api"), RESULTS)


def test_results_as_a_table_a_dataframe_and_sql(synthetic: Path) -> None:
    experiment = sweep3d.load(synthetic)
    table = experiment.results()
    assert table.num_rows == RESULTS and {"job", "object", "correct", "orientation_yaw"} <= set(table.column_names)
    frame = experiment.dataframe()
    assert len(frame) == RESULTS and list(frame.columns) == table.column_names
    assert frame["job"].is_monotonic_increasing
    counted = experiment.sql("SELECT count(*) AS n, sum(correct::int) AS right FROM results;")
    assert counted.to_pylist() == [{"n": RESULTS, "right": int(frame["correct"].sum())}]
    with pytest.raises(UserError, match=r"^query refused COPY: .*write them with pyarrow or pandas"):
        experiment.sql(f"COPY results TO '{synthetic.parent}/x.csv'")
    with pytest.raises(UserError, match="^query failed: "):
        experiment.sql("SELECT nope FROM results")
    with pytest.raises(UserError, match="the spec tests one model"):
        experiment.compare()


def test_no_results_yet_says_to_run_first(tmp_path: Path) -> None:
    write_cube(tmp_path)
    with pytest.raises(UserError, match=r"no results for experiment 'tiny' yet in .*; run it first"):
        sweep3d.load(tomllib.loads(TINY_SPEC), base=tmp_path).results()


def test_the_report_is_the_commands(synthetic: Path, tmp_path: Path) -> None:
    path = sweep3d.load(synthetic).report(tmp_path / "page.html")
    assert path == tmp_path / "page.html" and "<html" in path.read_text()[:200].lower()


def test_plan_returns_the_status_the_plan_command_prints(tmp_path: Path) -> None:
    """The numbers of ``sweep3d plan`` are the engine's: ``Experiment.plan()`` returns them."""
    from typer.testing import CliRunner

    from sweep3d.cli import app

    spec = write_spec(tmp_path, TINY_SPEC)
    status = sweep3d.load(spec).plan()
    assert [(s.stage, s.needed, s.cached, s.to_compute) for s in status.stages] == [
        ("render", 4, 0, 4), ("postprocess", 4, 0, 4), ("infer", 8, 0, 8)]  # blur: no render; sigma 0: no image
    assert status.seconds == sum(s.seconds for s in status.stages) > 0
    assert len(status.jobs) == 8 and status.to_render == 4
    printed = CliRunner().invoke(app, ["plan", str(spec)])
    assert printed.exit_code == 0, printed.output
    assert all(f"{s.stage} " in printed.output for s in status.stages)
