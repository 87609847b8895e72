"""The renderer seam: engines are backends registered by name, and a new one is one folder.

A fake third engine (``tests/stages/render/fake_engine/``), registered here, is planned like the
built-in two: ``[render] engine`` accepts it, its key part keys its renders apart, what it declares
it cannot render is refused at ``plan`` in one line. Nothing renders.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.spec import ENGINES
from sweep3d.spec.framing import Framing
from sweep3d.stages.render import BACKENDS, RENDERED_CONTROLS, engine_key
from sweep3d.stages.render.worker import make_scene
from sweep3d.stages.render.worker_protocol import RenderSettings
from tests.helpers import REPO, TINY_SPEC, load_spec, one_line, plan_for, scene_render_keys, write_spec
from tests.stages.render.fake_engine import FakeBackend, FlatScene


@pytest.fixture
def fake() -> Iterator[FakeBackend]:
    backend = BACKENDS.register("fake")(FakeBackend())
    try:
        yield backend
    finally:
        BACKENDS.unregister("fake")


def spec_with(folder: Path, render: str = "", extra: str = "", report: str = "") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    body = TINY_SPEC.replace("denoise = false\n", f"denoise = false\n{render}", 1)
    return write_spec(folder, body + extra + report)


def plan(path: Path) -> tuple[int, str]:
    result = CliRunner().invoke(app, ["plan", str(path)])
    return result.exit_code, result.output


def test_a_third_engine_in_one_folder_plans_a_spec(tmp_path: Path, fake: FakeBackend) -> None:
    cycles = scene_render_keys(spec_with(tmp_path / "c"))
    keys = scene_render_keys(spec_with(tmp_path / "f", 'engine = "fake"\n'))
    assert set(keys) == set(cycles) and not set(keys.values()) & set(cycles.values())  # keyed apart, job for job
    assert engine_key("fake") == fake.key()
    loaded = load_spec(spec_with(tmp_path / "g", 'engine = "fake"\ndevice = "auto"\n'))
    assert plan_for(loaded, "stand-in").device == "cpu"  # the one device it lists
    settings = RenderSettings.from_spec(loaded.render, Framing.full(loaded.render.resolution))
    assert isinstance(make_scene(settings, tmp_path), FlatScene)  # the worker builds the engine's scene


def test_what_the_engine_declares_it_cannot_render_is_refused_at_plan_in_one_line(tmp_path: Path,
                                                                                  fake: FakeBackend) -> None:
    turning = '[[controls]]\ntype = "hdri"\nrotation = [0, 90]\n'
    code, output = plan(spec_with(tmp_path / "a", 'engine = "fake"\n', turning))
    line = one_line(output)
    assert code == 2 and "controls[2]" in line and "'hdri'" in line and "its world cannot turn" in line
    assert 'engine "fake"' in line
    assert plan(spec_with(tmp_path / "b", "", turning))[0] == 0  # Cycles turns it
    dimmed = '[[controls]]\ntype = "hdri"\nstrength = [0.5, 1.0]\n'
    assert plan(spec_with(tmp_path / "c", 'engine = "fake"\n', dimmed))[0] == 0  # only what it declares
    code, output = plan(spec_with(tmp_path / "d", 'engine = "fake"\n', report="[report]\npart_visibility = true\n"))
    assert code == 2 and "report.part_visibility" in one_line(output)  # a pass it does not list


def test_an_unknown_engine_is_one_line_at_load(tmp_path: Path) -> None:
    code, output = plan(spec_with(tmp_path, 'engine = "mitsuba3"\n'))
    line = one_line(output)
    assert code == 2 and "render.engine" in line and "did you mean 'mitsuba'" in line
    assert "use one of cycles, mitsuba" in line


def test_the_built_in_engines_are_the_registry_s_with_cycles_the_default() -> None:
    from sweep3d.spec import RenderSpec

    assert sorted(ENGINES) == BACKENDS.names() and ENGINES[0] == RenderSpec().engine == "cycles"


def test_each_declared_refusal_names_a_built_in_control() -> None:
    """A renamed control cannot silently lose what an engine refuses of it."""
    for name in BACKENDS.names():
        assert set(BACKENDS.get(name).support) <= set(RENDERED_CONTROLS.names()), name


def test_the_registry_loads_neither_renderer() -> None:
    probe = ("from sweep3d.stages.render import BACKENDS, engine_key\n"
             "[BACKENDS.get(n).key() for n in BACKENDS.names()]\n"
             "import json, sys\nprint(json.dumps(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, check=True)
    loaded = set(json.loads(out.stdout.splitlines()[-1]))
    assert not {"bpy", "mitsuba", "drjit"} & loaded
