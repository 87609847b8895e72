"""The runner is the one place that wires the standard stages: no module outside it (and the
driver and stages beneath it) makes a render, postprocess or infer stage or runs stages itself.
A computation hands the runner a plan, names the standard stages it wants (and their variant:
every image stored, a timed render stage) and adds stages of its own only after them (the
stability check's). Its variants are the runner's, tested here without a render."""

from __future__ import annotations

import ast
from pathlib import Path
from types import SimpleNamespace

import pytest

from sweep3d.cache import Store
from sweep3d.runner import Runner
from sweep3d.stages.infer import InferStage
from sweep3d.stages.postprocess import PostprocessStage
from sweep3d.stages.render import RenderStage
from tests.helpers import REPO, TINY_SPEC, load_spec, write_spec

PACKAGE = REPO / "sweep3d"
BENEATH = ("runner", "driver", "stages")  # the runner, and what it wires
WIRING = {"RenderStage", "PostprocessStage", "InferStage", "run_stages"}


def wiring_calls(path: Path) -> list[str]:
    """Each call in ``path`` that makes a standard stage or runs stages: ``name:line``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Call):
            func = node.func
            if isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name) and func.value.id in WIRING:
                func = func.value  # PostprocessStage.for_spec(...)
            name = func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else ""
            if name in WIRING:
                found.append(f"{name}:{node.lineno}")
    return found


def test_no_module_outside_the_runner_wires_stages() -> None:
    outside = [path for path in sorted(PACKAGE.rglob("*.py"))
               if path.relative_to(PACKAGE).parts[0] not in BENEATH]
    wired = [f"{path.relative_to(REPO)}: {', '.join(calls)}" for path in outside if (calls := wiring_calls(path))]
    assert not wired, "hand the runner a plan and name the stages (Runner.run): \n" + "\n".join(wired)


def test_the_scan_sees_a_module_that_wires_stages(tmp_path: Path) -> None:
    module = tmp_path / "wires.py"
    module.write_text("from x import stages\nstages.RenderStage(e)\nrun_stages([a], plan, store, p)\n"
                      "PostprocessStage.for_spec(spec)\nother.for_spec(spec)\n")
    assert wiring_calls(module) == ["RenderStage:2", "run_stages:3", "PostprocessStage:4"]


@pytest.fixture
def runner(tmp_path: Path) -> Runner:
    spec = load_spec(write_spec(tmp_path, TINY_SPEC))
    return Runner(spec, Store(spec.store))


def test_the_variants_of_the_standard_stages_are_the_runner_s(runner: Runner) -> None:
    model = SimpleNamespace(digest="d", label="m")  # a model as the runner tells models apart
    render, post, infer = runner.stages(model, every_image=True, timings={})  # type: ignore[arg-type]
    assert isinstance(render, RenderStage) and render is not runner.render and render.timings == {}
    assert isinstance(post, PostprocessStage) and post.store_images and post.handoff is None
    assert post is not runner.post and runner.stages(names=("postprocess",), every_image=True) == (post,)
    assert isinstance(infer, InferStage) and infer.handoff is None and infer.blob_inputs == ("renders", "images")
    plain = runner.stages(model)  # type: ignore[arg-type]
    assert plain[0] is runner.render and plain[1] is runner.post and plain[2] is not infer
    assert runner.stages(model)[2] is plain[2]  # type: ignore[arg-type]  (one per model: it loads once)
