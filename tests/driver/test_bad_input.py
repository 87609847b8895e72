"""A plug-in that calls ``sys.exit`` — any code, 0 and None too — fails the command: exit code 2 and
one line naming the plug-in and the call, where it used to end ``sweep3d`` with the plug-in's code
(0: nothing ran, and CI saw success). A rendered control's ``edit`` that ends the render worker
(``os._exit``) or leaves the scene without its camera is named the same way, where each job's
line used to say only that the worker died or that Blender had no camera.

The cases met before anything renders or loads a model (a module's import, a model factory, a
policy, a rendered control's ``apply`` in the planner's in-frame test) run in the fast lane, for
``plan`` and ``run``; those met in a run (a control's ``edit`` in the render worker, a post
control, an evaluator) render one job at 32².
"""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from tests.helpers import TINY_SPEC, write_spec

#: One job (a yaw, a blur, one environment), so a run renders once.
ONE_JOB = TINY_SPEC.replace("yaw = [0, 45]", "yaw = [0]").replace("sigma = [0.0, 1.5]", "sigma = [0.0]").replace(
    '[[environments]]\nname = "studio"\nhdri = "builtin:studio"\n\n', "")

CONTROLS = '''
import sys

from pydantic import Field
from sweep3d.plugins import ControlParams, PostControl, RenderedControl


class Turn(RenderedControl):
    class Params(ControlParams):
        angle: float = Field(0.0)

    def apply(self, state, params):
        sys.exit(0)


class Cut(RenderedControl):
    class Params(ControlParams):
        angle: float = Field(0.0)

    def edit(self, scene, params):
        sys.exit(0)


class Fade(PostControl):
    class Params(ControlParams):
        amount: float = Field(0.0)

    def apply(self, image, params, rng):
        sys.exit(0)
'''
EDITS = '''
import os
import sys

from pydantic import Field
from sweep3d.plugins import ControlParams, RenderedControl


class Three(RenderedControl):
    class Params(ControlParams):
        angle: float = Field(0.0)

    def edit(self, scene, params):
        sys.exit(3)


class Gone(RenderedControl):
    class Params(ControlParams):
        angle: float = Field(0.0)

    def edit(self, scene, params):
        os._exit(3)


class NoCamera(RenderedControl):
    class Params(ControlParams):
        angle: float = Field(0.0)

    def edit(self, scene, params):
        scene.bpy.data.objects.remove(scene.camera, do_unlink=True)
'''
POLICY = '''
import sys

from sweep3d.plugins import Policy


class Quit(Policy):
    def count(self, shape):
        return None

    def arrays(self, shape, seed, history):
        sys.exit()
'''
BINDING_POLICY = '''
import sys

from sweep3d.plugins import Policy


class Quit(Policy):
    def bind(self, base, controls, objects, environments):
        sys.exit(0)
'''
FACTORY = '''
import sys


def make():
    sys.exit(0)
'''
EVALUATOR = '''
import sys

from sweep3d.stages.infer.evaluators import ClassificationEvaluator


class Bye(ClassificationEvaluator):
    def evaluate(self, logits, truths, labels):
        sys.exit(0)
'''


def _control(line: str) -> tuple[str, str]:
    """A spec edit adding one control (``line``: its type and values) before the policy."""
    return "[policy]", f"[[controls]]\n{line}\n\n[policy]"


#: id: (module source, the spec's edit with MOD for the module's name, the line's start with MOD and SPEC)
LOAD_CASES = {
    "control-module-import-exit-0": ("import sys\nsys.exit(0)\n", _control('type = "MOD:Ctrl"\nangle = [1.0]'),
                                     "error: SPEC: controls[2].type: control 'MOD:Ctrl' (MOD.py:2) called sys.exit(0) "
                                     "on import; a plug-in must not end sweep3d: raise an exception to fail"),
    "policy-module-import-exit-none": ("import sys\nsys.exit()\n", ('type = "grid"', 'type = "MOD:Quit"'),
                                       "error: SPEC: policy.type: policy 'MOD:Quit' (MOD.py:2) called sys.exit() on import"),
    "evaluator-module-import-exit-3": ("import sys\nsys.exit(3)\n", ("[model]\n", '[evaluator]\nkind = "MOD:Bye"\n\n[model]\n'),
                                       "error: SPEC: evaluator.kind: evaluator 'MOD:Bye' (MOD.py:2) called sys.exit(3) "
                                       "on import"),
    "model-module-import-exit-text": ("import sys\nsys.exit('no GPU')\n", ("[model]\n", '[model]\nname = "MOD:make"\n'),
                                      "error: SPEC: model.name: model 'MOD:make' (MOD.py:2) called sys.exit('no GPU') "
                                      "on import"),
    "model-factory-exit-0": (FACTORY, ("[model]\n", '[model]\nname = "MOD:make"\n'),
                             "error: SPEC: model.name: model factory 'MOD:make' (MOD.py:6) called sys.exit(0);"),
    "policy-arrays-exit-none": (POLICY, ('type = "grid"', 'type = "MOD:Quit"'),
                                "error: policy MOD:Quit (MOD.py:12) called sys.exit() in arrays();"),
    "rendered-control-apply-exit-0": (CONTROLS, _control('type = "MOD:Turn"\nangle = [1.0]'),  # the in-frame test
                                      "error: control 'MOD:Turn' (id 'Turn') (MOD.py:13) called sys.exit(0) in apply();"),
    # a hook no boundary wraps: the CLI's own net still fails the command, naming the file and line
    "policy-bind-exit-0": (BINDING_POLICY, ('type = "grid"', 'type = "MOD:Quit"'),
                           "error: a plug-in (MOD.py:9) called sys.exit(0); a plug-in must not end sweep3d"),
}


def _write_case(folder: Path, case: str, source: str, edit: tuple[str, str], spec_text: str = TINY_SPEC) -> tuple[Path, str]:
    """The case's module (named after it: every test's module is its own) and spec; returns the
    spec's path and the module's name."""
    module = "exit_" + case.replace("-", "_")
    (folder / f"{module}.py").write_text(textwrap.dedent(source))
    old, new = edit
    assert old in spec_text, old
    return write_spec(folder, spec_text.replace(old, new.replace("MOD", module), 1)), module


def _one_error_line(result) -> str:
    """The command's single ``error:`` line (no traceback), spaces as printed on one line."""
    assert "Traceback" not in result.output, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, result.output
    return " ".join(result.output[result.output.index("error:"):].split())


@pytest.mark.parametrize("command", ["plan", "run"])
@pytest.mark.parametrize("case", list(LOAD_CASES))
def test_a_plug_in_that_exits_before_anything_runs_fails_in_one_line(tmp_path: Path, case: str, command: str,
                                                                     monkeypatch) -> None:
    source, edit, expected = LOAD_CASES[case]
    spec, module = _write_case(tmp_path, case, source, edit)
    monkeypatch.delitem(sys.modules, module, raising=False)
    result = CliRunner().invoke(app, [command, str(spec), *(["--no-report"] if command == "run" else [])],
                                terminal_width=400)
    assert result.exit_code == 2, result.output
    assert _one_error_line(result).startswith(expected.replace("MOD", module).replace("SPEC", str(spec))), result.output
    assert not (tmp_path / "store" / "renders").exists()  # nothing ran


@pytest.mark.slow
@pytest.mark.parametrize(("case", "source", "edit", "expected"), [
    pytest.param("edit-in-the-render-worker", CONTROLS, _control('type = "MOD:Cut"\nangle = [1.0]'),
                 "error: control 'MOD:Cut' (id 'Cut') (MOD.py:21) called sys.exit(0) in edit();", id="worker-edit"),
    pytest.param("edit-exit-3", EDITS, _control('type = "MOD:Three"\nangle = [1.0]'),
                 "error: control 'MOD:Three' (id 'Three') (MOD.py:14) called sys.exit(3) in edit();", id="worker-edit-3"),
    pytest.param("edit-os-exit", EDITS, _control('type = "MOD:Gone"\nangle = [1.0]'),
                 "error: control 'MOD:Gone' (id 'Gone') ended the render worker in edit() (exit code 3), twice; a "
                 "plug-in must not end its process", id="worker-edit-os-exit"),
    pytest.param("edit-removes-the-camera", EDITS, _control('type = "MOD:NoCamera"\nangle = [1.0]'),
                 "error: control 'MOD:NoCamera' (id 'NoCamera') removed the scene's camera in edit(); an edit() may "
                 "replace the camera", id="worker-edit-no-camera"),
    pytest.param("post-control-apply", CONTROLS, _control('type = "MOD:Fade"\namount = [0.5]'),
                 "error: control 'MOD:Fade' (id 'Fade') (MOD.py:29) called sys.exit(0) in apply();", id="post-apply"),
    pytest.param("evaluator-evaluate", EVALUATOR, ("[model]\n", '[evaluator]\nkind = "MOD:Bye"\n\n[model]\n'),
                 "error: evaluator MOD:Bye (MOD.py:9) called sys.exit(0) in evaluate();", id="evaluate"),
])
def test_a_plug_in_that_exits_in_a_run_fails_it_in_one_line(tmp_path: Path, case: str, source: str,
                                                           edit: tuple[str, str], expected: str, monkeypatch) -> None:
    spec, module = _write_case(tmp_path, case, source, edit, ONE_JOB)
    monkeypatch.delitem(sys.modules, module, raising=False)
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"], terminal_width=400)
    assert result.exit_code == 2, result.output
    assert _one_error_line(result).startswith(expected.replace("MOD", module)), result.output


def test_a_worker_that_dies_in_a_users_edit_is_named_for_its_control() -> None:
    """The pool's side of the os._exit case above, without Blender: the worker said whose edit()
    it ran (an ``Editing`` message with the control's id) before it died; a built-in's edit is
    sweep3d's own failure, not named as the user's."""
    from types import SimpleNamespace

    from sweep3d.stages.render.pool import _failure, _user_editing, _Worker, died
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderJob

    gone, builtin = SimpleNamespace(type_name="mod:Gone", id="Gone"), SimpleNamespace(type_name="material", id="paint")
    job = RenderJob("k", "cube.obj", EnvironmentRef(color=(1.0, 1.0, 1.0)), controls=((builtin, None), (gone, None)))
    worker = _Worker(SimpleNamespace(exitcode=3), None, 0, task=[job], current="k", editing="Gone")
    label = "control 'mod:Gone' (id 'Gone')"
    killer = _user_editing(worker)
    assert killer == label
    assert died(worker, killer) == f"{label} ended the render worker in edit() (exit code 3)"
    reply = _failure(job, died(worker, killer), False, 600.0, killer)
    assert reply.kind == "plugin" and reply.error.startswith(f"{label} ended the render worker in edit() (exit code 3), "
                                                            "twice; a plug-in must not end its process")
    worker.editing = "paint"
    assert _user_editing(worker) is None
    worker.editing = None
    assert _user_editing(worker) is None and died(worker, None) == "render worker died (exit code 3)"


def test_an_edit_that_leaves_no_camera_is_named() -> None:
    from types import SimpleNamespace

    from sweep3d.stages.render.cycles.scene_edit import camera_problem

    camera = SimpleNamespace(name="Camera")
    assert camera_problem(SimpleNamespace(camera=camera, objects={"Camera": camera})) is None
    assert camera_problem(SimpleNamespace(camera=None, objects={})) == "removed the scene's camera"
    assert camera_problem(SimpleNamespace(camera=camera, objects={})) == "unlinked the scene's camera from the scene"


def test_a_reader_that_closes_the_pipe_early_is_not_blamed_on_a_plug_in(tmp_path: Path) -> None:
    """``sweep3d plan … | head -1``: rich exits when the pipe closes; that is no plug-in's exit."""
    import subprocess

    spec = write_spec(tmp_path, TINY_SPEC)
    child = subprocess.Popen([sys.executable, "-m", "sweep3d", "plan", str(spec)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE)
    child.stdout.close()  # the reader is gone before anything is printed
    _, err = child.communicate(timeout=120)
    assert b"plug-in" not in err and b"Traceback" not in err, err.decode()
