"""A user's plug-ins beside the spec: found from any working directory, and keyed by their code, so
editing one redoes exactly the stages it feeds (and ``plan`` says so)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.stages.infer.tasks import model_outputs
from tests.conftest import write_spec

pytestmark = pytest.mark.slow

SCENE_CONTROL = '''
from pydantic import Field
from sweep3d.controls import ControlParams
from sweep3d.stages.render import RenderedControl

RED = (1.0, 0.0, 0.0, 1.0)


class Slab(RenderedControl):
    class Params(ControlParams):
        size: float = Field(0.0, ge=0.0)

    def edit(self, scene, params):
        bpy = scene.bpy
        s = params.size
        mesh = bpy.data.meshes.new("slab")
        mesh.from_pydata([(-s, -1.5, -s), (s, -1.5, -s), (s, -1.5, s), (-s, -1.5, s)], [], [(0, 1, 2, 3)])
        material = bpy.data.materials.new("slab")
        material.use_nodes = True
        material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = RED
        mesh.materials.append(material)
        scene.add(bpy.data.objects.new("slab", mesh))
'''
POST_CONTROL = '''
from pydantic import Field
from sweep3d.controls import ControlParams
from sweep3d.stages.postprocess import PostControl

FACTOR = 0.5


class Dim(PostControl):
    class Params(ControlParams):
        strength: float = Field(0.0, ge=0.0, le=1.0)

    def apply(self, image, params, rng):
        return image * (1.0 - FACTOR * params.strength)
'''
EVALUATOR = '''
from sweep3d.stages.infer.evaluators import ClassificationEvaluator

NOTE = "first"


class Strict(ClassificationEvaluator):
    """Classification as usual (its code is what the test edits)."""
'''
SPEC = """\
[experiment]
name = "plugins"
store = "store"

[render]
resolution = 32
samples = 1
denoise = false

[evaluator]
kind = "myeval:Strict"

[[objects]]
name = "box"
mesh = "cube.obj"
labels = ["carton"]

[[environments]]
name = "white"
color = [1.0, 1.0, 1.0]

[[controls]]
type = "myscene:Slab"
size = [0.0, 0.6]

[[controls]]
type = "mypost:Dim"
strength = [0.0, 0.5]

[policy]
type = "grid"
"""


def counts(folder: Path) -> dict[str, int]:
    con = Store(folder / "store").connect()
    return {t: con.execute(f"SELECT count(*) FROM {t}").fetchone()[0] for t in ("renders", "images", "predictions")}


def edit(path: Path, old: str, new: str) -> None:
    path.write_text(path.read_text().replace(old, new))
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))  # a new mtime even on coarse clocks


def test_plugins_beside_the_spec_run_from_elsewhere_and_edits_redo_exactly_their_stages(tmp_path: Path,
                                                                                         monkeypatch) -> None:
    folder = tmp_path / "study"
    folder.mkdir()
    spec = write_spec(folder, SPEC)
    (folder / "myscene.py").write_text(textwrap.dedent(SCENE_CONTROL))
    (folder / "mypost.py").write_text(textwrap.dedent(POST_CONTROL))
    (folder / "myeval.py").write_text(textwrap.dedent(EVALUATOR))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    # the console script, from another folder, with nothing on PYTHONPATH: the spec's folder is found
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run([str(Path(sys.executable).parent / "sweep3d"), "run", str(spec), "--no-report"],
                          cwd=elsewhere, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert counts(folder) == {"renders": 2, "images": 2, "predictions": 4}  # an image with no post is its render

    runner = CliRunner()
    edit(folder / "myscene.py", "RED = (1.0, 0.0, 0.0, 1.0)", "RED = (0.0, 0.0, 1.0, 1.0)")
    plan = runner.invoke(app, ["plan", str(spec)])
    assert "myscene:Slab changed since the last run: 1 to render" in plan.output, plan.output
    assert "mypost:Dim" not in plan.output
    assert runner.invoke(app, ["run", str(spec), "--no-report"]).exit_code == 0
    assert counts(folder) == {"renders": 3, "images": 3, "predictions": 6}  # the slab's render, its images

    edit(folder / "mypost.py", "FACTOR = 0.5", "FACTOR = 0.25")
    plan = runner.invoke(app, ["plan", str(spec)])
    assert "mypost:Dim changed since the last run: 2 to postprocess" in plan.output, plan.output
    assert runner.invoke(app, ["run", str(spec), "--no-report"]).exit_code == 0
    assert counts(folder) == {"renders": 3, "images": 5, "predictions": 8}  # nothing rendered

    edit(folder / "myeval.py", 'NOTE = "first"', 'NOTE = "second"')
    plan = runner.invoke(app, ["plan", str(spec)])
    assert "myeval:Strict changed since the last run: 4 to infer" in plan.output, plan.output
    from sweep3d.stages.infer import stage

    batches = []  # the model's runs on the run's images (its one-image probe on a blank aside)
    monkeypatch.setattr(stage, "model_outputs", lambda model, images, *args: batches.append(len(images)) or
                        model_outputs(model, images, *args))
    assert runner.invoke(app, ["run", str(spec), "--no-report"]).exit_code == 0
    assert counts(folder) == {"renders": 3, "images": 5, "predictions": 12}  # re-evaluated only
    assert batches == [1], "the model's outputs for the 4 images were kept: it ran on none of them"

    plan = runner.invoke(app, ["plan", str(spec)])
    assert "changed since the last run" not in plan.output


HANGING_POST = '''
import os
import time
from pathlib import Path

from pydantic import Field
from sweep3d.controls import ControlParams
from sweep3d.stages.postprocess import PostControl


class Hang(PostControl):
    class Params(ControlParams):
        seconds: float = Field(0.0, ge=0.0)

    def apply(self, image, params, rng):
        Path(os.environ["HANG_MARK"]).touch()
        time.sleep(params.seconds)
        return image
'''


def test_ctrl_c_stops_a_run_whose_post_control_hangs(tmp_path: Path) -> None:
    import signal
    import time

    (tmp_path / "hang.py").write_text(textwrap.dedent(HANGING_POST))
    spec = write_spec(tmp_path, SPEC.replace('kind = "myeval:Strict"', 'kind = "classification"').replace(
        'type = "myscene:Slab"\nsize = [0.0, 0.6]', 'type = "hang:Hang"\nseconds = [100000.0]').replace(
        '[[controls]]\ntype = "mypost:Dim"\nstrength = [0.0, 0.5]\n', ""))
    mark = tmp_path / "hanging"
    process = subprocess.Popen([sys.executable, "-m", "sweep3d", "run", str(spec), "--no-report"], cwd=tmp_path,
                               env={**os.environ, "HANG_MARK": str(mark)}, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 120
        while not mark.exists() and time.monotonic() < deadline and process.poll() is None:
            time.sleep(0.2)
        assert mark.exists(), process.communicate(timeout=5)[0]
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=15)  # the hung thread is left behind: it is a daemon
    finally:
        process.kill()
    assert process.returncode == 130, output
    assert "interrupted: everything finished so far is stored" in output
    assert len(Store(tmp_path / "store").keys("renders")) == 1, "the render made before the hang is kept"


RAISING_POST = '''
from pydantic import Field
from sweep3d.plugins import ControlParams, PostControl


class Smear(PostControl):
    class Params(ControlParams):
        amount: float = Field(0.0, ge=0.0)

    def apply(self, image, params, rng):
        raise ValueError(f"cannot smear by {params.amount}")
'''
SHORT_EVALUATOR = '''
from sweep3d.stages.infer.evaluators import ClassificationEvaluator


class FirstOnly(ClassificationEvaluator):
    def evaluate(self, logits, truths, labels):
        return super().evaluate(logits, truths, labels)[:1]  # one row, whatever the batch
'''


def test_a_post_control_that_raises_stops_the_run_in_one_line_and_keeps_the_renders(tmp_path: Path) -> None:
    (tmp_path / "smear.py").write_text(textwrap.dedent(RAISING_POST))
    spec = write_spec(tmp_path, SPEC.replace('kind = "myeval:Strict"', 'kind = "classification"').replace(
        'type = "myscene:Slab"\nsize = [0.0, 0.6]', 'type = "smear:Smear"\namount = [0.5]').replace(
        '[[controls]]\ntype = "mypost:Dim"\nstrength = [0.0, 0.5]\n', ""))
    runner = CliRunner()
    result = runner.invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 2, result.output
    error = [line for line in result.output.splitlines() if "error:" in line]
    assert len(error) == 1 and "Traceback" not in result.output, result.output
    line = " ".join(result.output[result.output.index("error:"):].split())
    assert line.startswith("error: control 'smear:Smear' (id 'Smear') (smear.py:11) failed in apply(): "
                           "ValueError: cannot smear by 0.5"), line
    assert len(Store(tmp_path / "store").keys("renders")) == 1, "the render is kept"
    debug = runner.invoke(app, ["--debug", "run", str(spec), "--no-report"])
    assert debug.exit_code == 2 and "Traceback" in debug.output and 'smear.py", line 11' in debug.output


@pytest.mark.torch
def test_an_evaluator_returning_too_few_rows_stops_the_run_in_one_line(tmp_path: Path) -> None:
    (tmp_path / "short.py").write_text(textwrap.dedent(SHORT_EVALUATOR))
    spec = write_spec(tmp_path, SPEC.replace('kind = "myeval:Strict"', 'kind = "short:FirstOnly"').replace(
        'type = "myscene:Slab"\nsize = [0.0, 0.6]', 'type = "orientation"\nyaw = [0, 90]').replace(
        '[[controls]]\ntype = "mypost:Dim"\nstrength = [0.0, 0.5]\n', ""))
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 2, result.output
    line = " ".join(result.output[result.output.index("error:"):].split())
    assert line.startswith("error: evaluator short:FirstOnly") and "1 row" in line and "2 images" in line, line
    assert "accuracy" not in result.output
    assert len(Store(tmp_path / "store").keys("renders")) == 2, "the renders are kept"


HANGING_EDIT = '''
import time

from pydantic import Field
from sweep3d.plugins import ControlParams, RenderedControl


class Stuck(RenderedControl):
    class Params(ControlParams):
        seconds: float = Field(0.0, ge=0.0)

    def edit(self, scene, params):
        time.sleep(params.seconds)
'''


def test_a_scene_edit_that_hangs_is_named_after_the_render_timeout(tmp_path: Path) -> None:
    (tmp_path / "stuck.py").write_text(textwrap.dedent(HANGING_EDIT))
    spec = write_spec(tmp_path, SPEC.replace('kind = "myeval:Strict"', 'kind = "classification"').replace(
        'type = "myscene:Slab"\nsize = [0.0, 0.6]', 'type = "stuck:Stuck"\nseconds = [100000.0]').replace(
        '[[controls]]\ntype = "mypost:Dim"\nstrength = [0.0, 0.5]\n', "").replace(
        "denoise = false\n", "denoise = false\ntimeout = 1\n"))
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 2, result.output
    line = " ".join(result.output[result.output.index("error:"):].split())
    assert line.startswith("error: control 'stuck:Stuck' (id 'Stuck') did not finish its job within render.timeout "
                           "= 1 s, twice: its edit() may hang"), line
