"""Shared fixtures: tiny specs with generated meshes, and one real end-to-end run per session.

The real run renders with Blender (32×32 pixels, 1 sample) and classifies with the real
pretrained model, so tests that read results exercise the whole pipeline, not a stand-in.
"""

from __future__ import annotations

import shutil
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

CUBE_OBJ = """\
# unit cube
v -1 -1 -1
v 1 -1 -1
v 1 1 -1
v -1 1 -1
v -1 -1 1
v 1 -1 1
v 1 1 1
v -1 1 1
f 1 2 3 4
f 5 8 7 6
f 1 5 6 2
f 2 6 7 3
f 3 7 8 4
f 5 1 4 8
"""


def write_cube(folder: Path, name: str = "cube.obj") -> Path:
    path = folder / name
    path.write_text(CUBE_OBJ)
    return path


def write_spec(folder: Path, body: str, *, cube: bool = True, name: str = "spec.toml") -> Path:
    """Write a spec into ``folder`` (with a cube mesh beside it unless ``cube`` is False)."""
    if cube:
        write_cube(folder)
    path = folder / name
    path.write_text(textwrap.dedent(body))
    return path


TINY_SPEC = """\
[experiment]
name = "tiny"
seed = 7
store = "store"

[render]
resolution = 32
samples = 1
denoise = false

[model]
batch_size = 8

[[objects]]
name = "box"
mesh = "cube.obj"
labels = ["carton"]

[[environments]]
name = "white"
color = [1.0, 1.0, 1.0]

[[environments]]
name = "studio"
hdri = "builtin:studio"

[[controls]]
type = "orientation"
yaw = [0, 45]

[[controls]]
type = "blur"
sigma = [0.0, 1.5]

[policy]
type = "grid"
"""


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory) -> Path:
    """A folder holding ``spec.toml`` and its store after one real ``sweep3d run`` (8 jobs)."""
    from typer.testing import CliRunner

    from sweep3d.cli import app

    folder = tmp_path_factory.mktemp("tiny_run")
    spec = write_spec(folder, TINY_SPEC)
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output
    return folder


@pytest.fixture
def tiny_copy(tiny_run: Path, tmp_path: Path) -> Path:
    """A private copy of the tiny run's folder (spec, mesh and store) that a test may change."""
    target = tmp_path / "run"
    shutil.copytree(tiny_run, target)
    return target


@pytest.fixture(scope="session")
def blender_scene(tmp_path_factory):
    """One Blender scene per test session (bpy holds one scene per process), 32×32, 1 sample,
    with ``.cube`` the path of a cube mesh. Tests call ``prepare`` for the object they need."""
    from sweep3d.stages.render.protocol import RenderSettings
    from sweep3d.stages.render.scene import BlenderScene

    folder = tmp_path_factory.mktemp("scene")
    scene = BlenderScene(RenderSettings(resolution=32, samples=1, denoise=False), folder)
    scene.cube = str(write_cube(folder))
    return scene
