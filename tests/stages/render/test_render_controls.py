"""Every rendered control, in a real Blender scene: changing its value changes the image, and
the ends of its range render finite pixels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sweep3d.assets.sources import builtin_hdris
from sweep3d.runner import builtin_catalogue as catalogue
from sweep3d.stages.render.controls import RenderedControl
from sweep3d.stages.render.state import SceneState
from sweep3d.stages.render.worker_protocol import EnvironmentRef

CONTROLS = catalogue().controls

pytestmark = pytest.mark.blender


def environment(kind: str) -> EnvironmentRef:
    if kind == "hdri":
        return EnvironmentRef(hdri=str(builtin_hdris()["sunset"]))
    return EnvironmentRef(color=(0.7, 0.75, 0.8))


def render(scene, mesh: str, env: EnvironmentRef, controls: list[tuple[str, dict]]) -> np.ndarray:
    state = SceneState()
    for name, values in sorted(controls, key=lambda c: CONTROLS.get(c[0]).order):
        control = CONTROLS.get(name)(name, name)
        assert isinstance(control, RenderedControl)
        control.apply(state, control.params(values))
    scene.prepare(mesh, env)
    scene.pose_scene(state)
    return scene.render()


@pytest.fixture(scope="module")
def texture(tmp_path_factory) -> Path:
    from PIL import Image

    path = tmp_path_factory.mktemp("tex") / "checker.png"
    checker = (np.indices((64, 64)).sum(axis=0) // 8 % 2 * 255).astype(np.uint8)
    Image.fromarray(np.stack([checker, 255 - checker, checker // 2], axis=-1)).save(path)
    return path


def cases(texture: Path):
    """(control, environment kind, value that changes the image, extreme values of its range)."""
    return [
        ("orientation", "plain", {"yaw": 40.0, "pitch": 25.0}, [{"yaw": -180.0, "pitch": 180.0, "roll": 180.0}]),
        ("camera", "plain", {"azimuth": 60.0, "elevation": 60.0},
         [{"elevation": 90.0}, {"elevation": -90.0}, {"zoom": 1e-3}, {"zoom": 1e3}, {"focal_length": 1.0},
          {"focal_length": 5000.0}, {"fstop": 1000.0}]),
        ("camera", "plain", {"fstop": 0.05, "zoom": 0.6}, [{"fstop": 0.01}]),
        ("position", "plain", {"x": 0.5, "y": 0.5}, [{"x": -100.0, "y": 100.0}]),
        ("scale", "plain", {"factor": 0.5}, [{"factor": 1e-6}, {"factor": 1e6}]),
        ("pin_to_ground", "plain", {"enabled": True}, [{"enabled": True}]),
        ("occlusion", "plain", {"coverage": 0.5, "direction": 90.0}, [{"coverage": 1.0}, {"coverage": 0.01}]),
        ("material", "plain", {"skin": "zebra"}, [{"skin": "zebra", "scale": 1000.0}, {"skin": "cow", "scale": 1e-3}]),
        ("material", "plain", {"skin": "tiger"}, []),
        ("material", "plain", {"skin": "cow"}, []),
        ("material", "plain", {"skin": "giraffe"}, []),
        ("material", "plain", {"skin": "leopard"}, []),
        ("material", "plain", {"skin": "image", "image": str(texture)}, []),
        ("point_light", "plain", {"watts": 200.0, "temperature": 2000.0},
         [{"watts": 1e7, "distance": 1.01}, {"watts": 1e-3, "distance": 1e4, "temperature": 40000.0}]),
        ("sun_light", "plain", {"strength": 3.0, "angle": 5.0, "temperature": 3000.0},
         [{"strength": 1e6, "angle": 180.0, "elevation": -90.0}, {"strength": 1e-6, "relative_to": "camera",
                                                                  "elevation": 90.0, "temperature": 40000.0}]),
        ("area_light", "plain", {"watts": 200.0, "size": 2.0, "relative_to": "camera"},
         [{"watts": 1e7, "distance": 1.01, "size": 1e4, "shape": "disk"}, {"watts": 1e-3, "distance": 1e4, "size": 1e-3}]),
        ("hdri", "hdri", {"rotation": 120.0}, [{"rotation": 180.0, "strength": 1e6}, {"strength": 1e-6}]),
        ("sky", "plain", {"enabled": True, "sun_elevation": 20.0},
         [{"enabled": True, "sun_elevation": -90.0}, {"enabled": True, "sun_elevation": 90.0, "strength": 1e6}]),
        ("background", "hdri", {"color": "#3366cc"}, [{"color": "#000000"}, {"color": "#FFFFFF"}]),
        ("denoiser", "hdri", {"mode": "on"}, [{"mode": "off"}]),
    ]


def test_every_rendered_control_is_covered(texture) -> None:
    rendered = {n for n in CONTROLS.names() if issubclass(CONTROLS.get(n), RenderedControl)}
    assert rendered == {c[0] for c in cases(texture)}


@pytest.mark.parametrize("index", range(20))
def test_control_changes_the_image_and_its_range_ends_are_finite(blender_scene, texture, index) -> None:
    name, env_kind, values, extremes = cases(texture)[index]
    env = environment(env_kind)
    mesh = blender_scene.cube
    base = render(blender_scene, mesh, env, [])
    changed = render(blender_scene, mesh, env, [(name, values)])
    assert np.isfinite(changed).all()
    assert np.abs(changed - base).mean() > 0.002, f"{name} {values} did not change the image"
    for extreme in extremes:
        image = render(blender_scene, mesh, env, [(name, extreme)])
        assert image.shape == base.shape and np.isfinite(image).all(), f"{name} {extreme}"
    again = render(blender_scene, mesh, env, [])  # every change is undone for the next job
    assert np.abs(again - base).mean() < 0.01


def test_occlusion_covers_the_side_it_comes_from(blender_scene) -> None:
    env = EnvironmentRef(color=(1.0, 1.0, 1.0))
    base = render(blender_scene, blender_scene.cube, env, [])
    right = render(blender_scene, blender_scene.cube, env, [("occlusion", {"coverage": 0.5, "direction": 0.0, "grey": 0.0})])
    diff = np.abs(right - base).mean(axis=2)
    assert diff[:, 16:].mean() > 3 * diff[:, :16].mean()


def test_a_procedural_sky_has_a_ground_below_the_horizon(blender_scene) -> None:
    env = environment("plain")
    looking_down = [("camera", {"elevation": 50.0}), ("sky", {"enabled": True, "sun_elevation": 30.0})]
    looking_up = [("camera", {"elevation": -50.0}), ("sky", {"enabled": True, "sun_elevation": 30.0})]
    down = render(blender_scene, blender_scene.cube, env, looking_down)
    up = render(blender_scene, blender_scene.cube, env, looking_up)
    corner = (slice(0, 4), slice(0, 4))  # background only
    ground, sky = down[corner].mean(), up[corner].mean()
    assert ground > 0.05, "below the horizon is not black"
    assert ground < sky, "the ground is dimmer than the sky (its albedo)"
