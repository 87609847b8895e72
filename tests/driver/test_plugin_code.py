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
from sweep3d.stages.infer.task_calls import model_outputs
from tests.helpers import SCENE_CONTROL, spec_toml, write_spec

pytestmark = pytest.mark.slow

POST_CONTROL = '''
from pydantic import Field
from sweep3d.core.control import ControlParams
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
SPEC = spec_toml("plugins", body="""\
[evaluator]
kind = "myeval:Strict"

[[controls]]
type = "myscene:Slab"
size = [0.0, 0.6]

[[controls]]
type = "mypost:Dim"
strength = [0.0, 0.5]

[policy]
type = "grid"
""")


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
    from sweep3d.stages.infer import infer_stage as stage

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
from sweep3d.core.control import ControlParams
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
    # Ctrl-C as in a terminal: the run starts with SIGINT's default action. A process started with
    # SIGINT ignored keeps ignoring it (Python honours an inherited SIG_IGN), and a test worker may
    # have it ignored by then (something earlier in the session: the run stayed in its loop).
    process = subprocess.Popen([sys.executable, "-m", "sweep3d", "run", str(spec), "--no-report"], cwd=tmp_path,
                               env={**os.environ, "HANG_MARK": str(mark)}, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
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


def stuck_spec(folder: Path, render: str = "") -> Path:
    """A spec whose only control is ``stuck:Stuck`` at 100000 s (every job's edit hangs), with
    ``render`` added to its ``[render]`` table."""
    (folder / "stuck.py").write_text(textwrap.dedent(HANGING_EDIT))
    return write_spec(folder, SPEC.replace('kind = "myeval:Strict"', 'kind = "classification"').replace(
        'type = "myscene:Slab"\nsize = [0.0, 0.6]', 'type = "stuck:Stuck"\nseconds = [100000.0]').replace(
        '[[controls]]\ntype = "mypost:Dim"\nstrength = [0.0, 0.5]\n', "").replace(
        "denoise = false\n", f"denoise = false\n{render}"))


def test_a_scene_edit_that_hangs_is_named_after_the_render_timeout(tmp_path: Path) -> None:
    spec = stuck_spec(tmp_path, "timeout = 1\n")
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 2, result.output
    line = " ".join(result.output[result.output.index("error:"):].split())
    assert line.startswith("error: control 'stuck:Stuck' (id 'Stuck') did not finish its job within render.timeout "
                           "= 1 s, twice: its edit() may hang"), line


def test_a_hung_edit_with_no_timeout_set_stops_the_run_after_the_default_edit_timeout(tmp_path: Path) -> None:
    """Issue 35, item 6: with no timeout in the spec a hung edit() ran on silently for
    render.timeout (600 s) twice. The default render.edit_timeout (60 s) ends it: exit 2, one
    line naming the control, where its edit() is and the job's values; not retried."""
    import time

    from sweep3d.spec.models import RenderSpec
    from tests.helpers import REPO

    spec = stuck_spec(tmp_path)
    assert "timeout" not in spec.read_text() and RenderSpec().edit_timeout == 60
    started = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "sweep3d", "run", str(spec), "--no-report"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300, env={**os.environ, "PYTHONPATH": str(REPO)})
    elapsed = time.monotonic() - started
    assert done.returncode == 2, done.stdout + done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    edit_line = 1 + textwrap.dedent(HANGING_EDIT).splitlines().index("    def edit(self, scene, params):")
    assert lines == [f"error: control 'stuck:Stuck' (id 'Stuck', stuck.py:{edit_line}): its edit() did not return "
                     "within render.edit_timeout = 60 s (seconds=100000.0); fix it if it hangs, or raise "
                     "render.edit_timeout if it is only slow"], done.stderr
    assert 60 < elapsed < 115, f"{elapsed:.0f} s: one edit_timeout and Blender's start, no retry (2 x 60 s)"
    assert "Traceback" not in done.stdout + done.stderr


FORKING_EDIT = '''
import multiprocessing
import os
import subprocess
import sys
import time

from pydantic import Field
from sweep3d.plugins import ControlParams, RenderedControl


class Forker(RenderedControl):
    """Leaves children running, every way an edit can: a subprocess, a bare fork, and multiprocessing
    (fork, and spawn, which starts the worker's resource tracker). All of them hold its stderr. And
    two that leave the worker's process group: a sleep in a session of its own, and a daemon's
    double fork (its parent exits at once), both marked by the argument $ESCAPED."""

    class Params(ControlParams):
        children: int = Field(0, ge=0)

    def edit(self, scene, params):
        pids = []
        for _ in range(params.children):
            pids.append(subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"]).pid)
            pid = os.fork()
            if pid == 0:
                time.sleep(600)
                os._exit(0)
            pids.append(pid)
            for method in ("fork", "spawn"):
                child = multiprocessing.get_context(method).Process(target=time.sleep, args=(600,))
                child.start()
                pids.append(child.pid)
            pids.append(multiprocessing.resource_tracker._resource_tracker._pid)
            subprocess.Popen(["sleep", os.environ["ESCAPED"]], start_new_session=True)
            subprocess.run(["sh", "-c", f"setsid sleep {os.environ['ESCAPED']} >/dev/null 2>&1 &"], check=True)
        with open(os.environ["FORKED"], "a") as out:
            out.write("".join(f"{pid}\\n" for pid in pids))
'''


def _session(sid: int) -> list[str]:
    """The live processes of session ``sid`` ("pid state command"), zombies left out."""
    out = subprocess.run(["ps", "-s", str(sid), "-o", "pid=,stat=,args="], capture_output=True, text=True).stdout
    return [line.strip() for line in out.splitlines() if line.strip() and line.split()[1][0] != "Z"]


def test_an_edit_that_forks_leaves_no_process_behind_and_the_run_s_pipe_closes(tmp_path: Path) -> None:
    """Issue 35, item 13: an edit's children (and a resource tracker) outlived the run and held its
    output pipe, so a caller reading it hung. Each worker leads its own process group, which goes
    with it: the run (in a session of its own) exits 0, its pipe closes, and no process of its
    session is left. Issue 45, item 2: nor is one the edit started in a session of its own, or
    whose parent exited (each worker adopts its orphans, and ends them before it exits)."""
    import signal

    from tests.helpers import REPO
    from tests.helpers.processes import marker, running

    escaped = marker()

    (tmp_path / "forker.py").write_text(FORKING_EDIT)
    spec = write_spec(tmp_path, SPEC.replace('kind = "myeval:Strict"', 'kind = "classification"').replace(
        'type = "myscene:Slab"\nsize = [0.0, 0.6]', 'type = "forker:Forker"\nchildren = [0, 1]').replace(
        '[[controls]]\ntype = "mypost:Dim"\nstrength = [0.0, 0.5]\n', ""))
    process = subprocess.Popen([sys.executable, "-m", "sweep3d", "run", str(spec), "--no-report"], cwd=tmp_path,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True,
                               env={**os.environ, "PYTHONPATH": str(REPO), "FORKED": str(tmp_path / "forked"),
                                    "ESCAPED": escaped})
    try:
        output, _ = process.communicate(timeout=240)  # EOF: nothing holds the pipe any more
        assert process.returncode == 0, output
        assert not _session(process.pid), f"left running after the run: {_session(process.pid)}"
        assert not running(escaped), f"left the worker's group and outlived the run: {running(escaped)}"
    finally:
        for pid in [int(line.split()[0]) for line in _session(process.pid)] + running(escaped):
            try:  # a failing test leaves no orphan either
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        process.kill()
    forked = (tmp_path / "forked").read_text().split()
    assert len(forked) == 5 and all(pid.isdigit() for pid in forked), forked  # four children and a tracker
    assert len(Store(tmp_path / "store").keys("renders")) == 2
