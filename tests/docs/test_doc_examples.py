"""The documentation's examples work as written and do what the pages say; the README keeps CI's
test command (every tutorial block also runs as written: tests/docs/test_tutorials.py)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest

from sweep3d.stages.postprocess import apply_post
from tests.helpers import REPO, TINY_SPEC, load_spec, plan_for, write_cube, write_spec
from tests.helpers.doc_blocks import block


def test_ci_runs_the_readmes_test_command() -> None:
    command = (REPO / ".ci" / "run").read_text().strip().splitlines()[-1]
    assert f"\n    {command}\n" in (REPO / "README.md").read_text()


def test_custom_control_from_the_docs(tmp_path: Path, monkeypatch) -> None:
    code = block("tutorials/own-control.md", "# Your own control")
    assert len(code.strip().splitlines()) < 30
    (tmp_path / "mycontrols.py").write_text(code)
    monkeypatch.syspath_prepend(str(tmp_path))
    spec = write_spec(tmp_path, TINY_SPEC.replace(
        "[policy]", '[[controls]]\ntype = "mycontrols:Vignette"\nstrength = [0, 0.5, 1]\n\n[policy]'))
    loaded = load_spec(spec)
    plan = plan_for(loaded, "m")
    assert len(plan.jobs) == 24
    # strength 0 is neutral: those jobs share their keys with a spec that lacks the control
    (tmp_path / "plain").mkdir()
    plain = plan_for(load_spec(write_spec(tmp_path / "plain", TINY_SPEC)), "m")
    neutral = {j.image_key for j in plan.jobs if j.values["Vignette"]["strength"] == 0}
    assert neutral == {j.image_key for j in plain.jobs}
    control = next(c for c in loaded.controls if c.id == "Vignette")
    image = np.ones((16, 16, 3), np.float32)
    out = apply_post(image, [control], {"Vignette": {"strength": 1.0}}, "ab" * 10)
    assert out[0, 0].max() < 0.05 and out[8, 8].min() > 0.9


DEPTH_MODEL = """
import torch
from sweep3d.stages.infer import Classifier, Normalize


class Constant(torch.nn.Module):
    def forward(self, x):
        return torch.full((x.shape[0], 1, *x.shape[-2:]), 3.0)


def constant():
    return Classifier(Constant(), Normalize())
"""


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.torch
def test_depth_evaluator_from_the_docs_reads_the_depth_pass(tmp_path: Path, monkeypatch) -> None:
    from typer.testing import CliRunner

    from sweep3d.cache.blobs import load_pass
    from sweep3d.cache.store import Store
    from sweep3d.cli import app
    from sweep3d.results import connect

    (tmp_path / "mydepth.py").write_text(block("how-to/own-evaluator.md", "# Your own evaluator"))
    (tmp_path / "depthmodel.py").write_text(DEPTH_MODEL)
    monkeypatch.syspath_prepend(str(tmp_path))
    spec = write_spec(tmp_path, TINY_SPEC.replace("[model]\n", '[model]\nname = "depthmodel:constant"\n').replace(
        "[policy]", '[evaluator]\nkind = "mydepth:DepthError"\n\n[policy]'))
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output
    store = Store(tmp_path / "store")
    rows = connect(store, "tiny").execute("SELECT truth_key, abs_rel, correct, valid FROM results").fetchall()
    assert len(rows) == 8
    for truth_key, abs_rel, correct, valid in rows:
        mask, depth = load_pass(store, truth_key, "mask"), load_pass(store, truth_key, "depth")
        expected = np.mean(np.abs(3.0 - depth[mask]) / depth[mask])  # by hand, from the passes
        assert valid and abs_rel == pytest.approx(expected, rel=1e-6) and correct == (expected < 0.1)


@pytest.mark.torch
def test_detector_factory_from_the_docs_loads_a_scripted_detector(tmp_path: Path, monkeypatch) -> None:
    from typing import Dict, List

    import torch

    from sweep3d.stages.infer import Detector
    from sweep3d.stages.infer.task_calls import check_task, model_outputs

    class Fixed(torch.nn.Module):
        def forward(self, images: List[torch.Tensor]) -> List[Dict[str, torch.Tensor]]:
            return [{"boxes": torch.tensor([[1.0, 2.0, 10.0, 12.0]]), "labels": torch.tensor([3]),
                     "scores": torch.tensor([0.8])} for _ in images]

    torch.jit.save(torch.jit.script(Fixed()), str(tmp_path / "detector.pt"))
    (tmp_path / "mydetectors.py").write_text(block("how-to/tasks.md", "A detector or segmenter is a factory"))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.chdir(tmp_path)
    from sweep3d.stages.infer import load_model

    model = load_model("mydetectors:my_detector")
    assert isinstance(model, Detector) and model.label_map().index("car") == 3
    check_task(model, "detection", "mydetectors:my_detector")
    found = model_outputs(model, np.zeros((2, 16, 16, 3), np.float32), "detection", "mydetectors:my_detector")
    assert len(found) == 2 and found[0].boxes.tolist() == [[1.0, 2.0, 10.0, 12.0]] and found[1].labels.tolist() == [3]


def test_custom_policy_from_the_docs(tmp_path: Path, monkeypatch) -> None:
    from sweep3d.stages.plan import count_jobs

    (tmp_path / "mypolicies.py").write_text(block("how-to/own-policy.md", "A policy turns a scene's search space"))
    monkeypatch.syspath_prepend(str(tmp_path))
    body = TINY_SPEC.replace("yaw = [0, 45]", "yaw = { range = [0, 90] }").replace(
        'type = "grid"', 'type = "mypolicies:Extremes"\nmiddle = true')
    loaded = load_spec(write_spec(tmp_path, body))
    plan = plan_for(loaded, "m")
    assert count_jobs(loaded) == len(plan.jobs) == 2 * 3 * 2  # 2 environments × 3 yaws × 2 sigmas
    assert sorted({j.values["orientation"]["yaw"] for j in plan.jobs}) == [0.0, 45.0, 90.0]


def api_example(folder: Path) -> str:
    """The notebook tutorial's example, its mesh a cube where Sweet Home 3D's furniture is missing."""
    code = block("tutorials/notebooks.md", "# Notebooks and the Python API")
    mesh = re.search(r'"(/usr/share/sweethome3d/[^"]+)"', code).group(1)
    if not Path(mesh.partition("#")[0]).exists():
        code = code.replace(mesh, str(write_cube(folder)))
    return code


def test_the_python_api_example_plans_four_jobs(tmp_path: Path, monkeypatch, capsys) -> None:
    code = api_example(tmp_path)
    monkeypatch.chdir(tmp_path)
    exec(code[:code.index("exp.run(")], {})  # up to the run: the spec is valid, nothing rendered
    assert capsys.readouterr().out == "4 jobs\n"


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.torch
def test_the_python_api_example_runs(tmp_path: Path, monkeypatch) -> None:
    code = api_example(tmp_path)
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(code, scope)
    frame = scope["df"]
    assert len(frame) == 4 and set(frame["blur_sigma"]) == {0.0, 2.0} and frame["valid"].all()
    assert scope["page"] == Path("notebook.html") and scope["page"].stat().st_size > 10_000
    assert scope["exp"].sql("SELECT count(*) AS n FROM results").to_pylist() == [{"n": 4}]


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.torch
@pytest.mark.parametrize("how", ["file", "stdin"])
def test_the_python_api_example_runs_as_a_plain_script(tmp_path: Path, how: str) -> None:
    """``python example.py`` and ``python - < example.py``, no ``if __name__ == "__main__":``: the
    render workers never run the user's script (issue 35, item 4: they ran it again, which found
    the store locked by its parent, or could not find ``<stdin>``)."""
    import subprocess
    import sys

    script = tmp_path / "example.py"
    script.write_text(api_example(tmp_path))
    command, stdin = ([sys.executable, str(script)], None) if how == "file" else ([sys.executable, "-"], script.open())
    try:
        done = subprocess.run(command, stdin=stdin, cwd=tmp_path, capture_output=True, text=True, timeout=600,
                              env={**os.environ, "PYTHONPATH": str(REPO)})
    finally:
        if stdin is not None:
            stdin.close()
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("4 jobs") == 1, done.stdout  # the script's body ran once, in its own process
    assert "Traceback" not in done.stderr, done.stderr
    assert (tmp_path / "notebook.html").stat().st_size > 10_000


@pytest.mark.blender
def test_scene_edit_control_from_the_docs_adds_its_disc_for_one_job(blender_scene, tmp_path: Path,
                                                                      monkeypatch) -> None:
    from io import BytesIO

    from PIL import Image

    from sweep3d.stages.render.worker import render_job
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderJob

    (tmp_path / "mydisc.py").write_text(block("tutorials/own-control.md", "A rendered control has two hooks"))
    monkeypatch.syspath_prepend(str(tmp_path))
    spec = write_spec(tmp_path, TINY_SPEC.replace(
        "[policy]", '[[controls]]\ntype = "mydisc:Disc"\nradius = [0, 1]\nred = 1.0\n\n[policy]'))
    control = next(c.control for c in load_spec(spec).controls if c.id == "Disc")

    def render(radius: float) -> np.ndarray:
        job = RenderJob(render_key="k", mesh=blender_scene.cube, environment=EnvironmentRef(color=(1.0, 1.0, 1.0)),
                        blob=str(tmp_path / "x.png"), controls=((control, control.params({"radius": radius, "red": 1.0})),))
        reply = render_job(blender_scene, job, keep_pixels=True)
        assert reply.ok and not reply.info.rebuilt, reply.error
        return np.asarray(Image.open(BytesIO(reply.png))).astype(int)

    plain = render(0.0)
    with_disc = render(1.0)  # a disc of the bounding sphere's radius sticks out of the cube
    assert ((with_disc[..., 0] - with_disc[..., 2]) > 60).sum() > ((plain[..., 0] - plain[..., 2]) > 60).sum()
    assert np.array_equal(render(0.0), plain)


@pytest.mark.torch
def test_classifier_factory_from_the_docs_loads_a_scripted_model_and_keys_its_code(tmp_path: Path,
                                                                                      monkeypatch) -> None:
    import torch

    from sweep3d.core.registry import code_identity
    from sweep3d.stages.infer import MODELS, Classifier, load_model

    class Linear(torch.nn.Module):
        def forward(self, x: torch.Tensor) -> torch.Tensor:
            return x.mean(dim=(2, 3)) @ torch.ones(3, 1000)

    torch.jit.save(torch.jit.script(Linear()), str(tmp_path / "my_model.pt"))
    (tmp_path / "mymodels.py").write_text(block("how-to/own-model.md", "# Your own model"))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.chdir(tmp_path)
    model = load_model("mymodels:resnet_like")
    assert isinstance(model, Classifier) and model.preprocess.crop == 224
    assert code_identity(MODELS.get("mymodels:resnet_like")).startswith("source:")


def test_the_readme_fits_a_screen_and_its_links_lead_into_the_docs() -> None:
    """The README stays short (issue 36: under 200 lines) and every relative link it gives exists,
    so the links work on GitHub as in a checkout."""
    text = (REPO / "README.md").read_text()
    assert len(text.splitlines()) < 200
    links = re.findall(r"\]\(((?!https?:)[^)#]+)(?:#[^)]*)?\)", text)
    assert len(links) > 30 and any(link.startswith("docs/tutorials/") for link in links)
    assert [link for link in links if not (REPO / link).exists()] == []
