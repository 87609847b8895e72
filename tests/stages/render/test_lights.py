"""Sun and area lights, camera-relative placement and a plain background's key light: the spec,
the keys, the geometry (fast) and real renders (Blender, 32-48 px, few samples)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.core.errors import SpecError
from sweep3d.spec.models import KeyLightSpec
from sweep3d.stages.render.lights import direction, facing, kelvin_to_rgb, light_colour
from sweep3d.stages.render.state import SceneState
from sweep3d.stages.render.worker_protocol import EnvironmentRef
from tests.helpers import TINY_SPEC, load_spec, plan_for, render, scene_render_keys, sphere_obj, write_spec

SUN = '[[controls]]\ntype = "sun_light"\n'
AREA = '[[controls]]\ntype = "area_light"\n'


def spec_with(tmp_path: Path, extra: str = "", env: str = "") -> Path:
    tmp_path.mkdir(parents=True, exist_ok=True)
    body = TINY_SPEC.replace('color = [1.0, 1.0, 1.0]\n', f'color = [1.0, 1.0, 1.0]\n{env}', 1)
    return write_spec(tmp_path, body + extra)


# -- the spec ---------------------------------------------------------------------------------

def test_a_plain_colour_gets_the_default_key_light_and_an_hdri_none(tmp_path) -> None:
    envs = {e.name: e for e in load_spec(spec_with(tmp_path)).environments}
    assert envs["white"].key_light == KeyLightSpec()
    assert envs["studio"].key_light is None


@pytest.mark.parametrize(("text", "expected"), [
    ("key_light = false\n", None),
    ("key_light = true\n", KeyLightSpec()),
    ("key_light = { strength = 4.0, azimuth = 30, fill = 0.2 }\n", KeyLightSpec(strength=4.0, azimuth=30, fill=0.2)),
])
def test_key_light_is_true_false_or_a_table(tmp_path, text: str, expected) -> None:
    white = load_spec(spec_with(tmp_path, env=text)).environments[0]
    assert white.key_light == expected


@pytest.mark.parametrize(("extra", "env", "key", "expect"), [
    (SUN + "strength = -1.0\n", "", "controls[2].strength", ("greater than or equal to 0",)),
    (SUN + "strength = nan\n", "", "controls[2].strength", ("not a finite number",)),
    (AREA + "watts = { range = [0, inf] }\n", "", "controls[2].watts", ("finite",)),
    (SUN + 'strength = 1.0\nrelative_to = "camrea"\n', "", "controls[2].relative_to", ("'camera'", "'world'")),
    (AREA + 'watts = 10.0\nshape = "circle"\n', "", "controls[2].shape", ("'square'", "'disk'")),
    (AREA + "watts = 10.0\nsize = 0\n", "", "controls[2].size", ("greater than 0",)),
    (AREA + "watts = 10.0\ndistance = 0.5\n", "", "controls[2].distance", ("greater than 1",)),
    ("", 'key_light = "yes"\n', "environments[0]", ("key_light must be true, false or a table",)),
    ("", "key_light = { strength = -2 }\n", "environments[0].key_light.strength", ("greater than 0",)),
    ("", "key_light = { fill = nan }\n", "environments[0].key_light.fill", ("finite",)),
    ("", "key_light = { strenght = 2 }\n", "environments[0].key_light.strenght", ("unknown key",)),
])
def test_a_bad_light_is_one_line_naming_the_file_and_key(tmp_path, extra: str, env: str, key: str, expect) -> None:
    path = spec_with(tmp_path, extra, env)
    with pytest.raises(SpecError) as caught:
        load_spec(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: {key}: ") and "\n" not in message
    for text in expect:
        assert text in message, message


def test_the_cli_says_a_negative_light_in_one_line_and_exits_2(tmp_path) -> None:
    path = spec_with(tmp_path, AREA + "watts = -5.0\n")
    result = CliRunner().invoke(app, ["plan", str(path)])
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert result.exit_code == 2 and len(lines) == 1, result.output
    assert lines[0].startswith("error:") and str(path) in lines[0] and "controls[2].watts" in lines[0]


# -- keys -------------------------------------------------------------------------------------

def test_lights_at_zero_render_nothing_new(tmp_path) -> None:
    plain = scene_render_keys(spec_with(tmp_path / "a"))
    assert scene_render_keys(spec_with(tmp_path / "b", SUN + 'strength = 0.0\nrelative_to = "camera"\n')) == plain
    assert scene_render_keys(spec_with(tmp_path / "c", AREA + "watts = [0.0]\nsize = 3.0\n")) == plain
    lit = {j.render_key for j in plan_for(load_spec(spec_with(tmp_path / "d", SUN + "strength = [0.0, 2.0]\n")),
                                          "stand-in").jobs}
    assert len(lit) == 2 * len(plain)  # strength 2 makes new renders, strength 0 is the old ones
    assert set(plain.values()) <= lit


def test_the_key_light_is_in_a_plain_colour_render_key_and_off_is_the_old_key(tmp_path) -> None:
    default = scene_render_keys(spec_with(tmp_path / "a"))
    off = scene_render_keys(spec_with(tmp_path / "b", env="key_light = false\n"))
    softer = scene_render_keys(spec_with(tmp_path / "c", env="key_light = { angle = 20 }\n"))
    for yaw in (0, 45):
        assert default["white", yaw] != off["white", yaw] != softer["white", yaw] != default["white", yaw]
        assert default["studio", yaw] == off["studio", yaw] == softer["studio", yaw]
    white = load_spec(spec_with(tmp_path / "d", env="key_light = false\n")).environments[0]
    assert white.key_part(None) == {"hdri": None, "color": [1.0, 1.0, 1.0], "strength": 1.0}  # as before lights


def test_a_camera_relative_key_light_keys_as_before_and_a_world_one_does_not(tmp_path) -> None:
    default = scene_render_keys(spec_with(tmp_path / "a"))
    riding = scene_render_keys(spec_with(tmp_path / "b", env='key_light = { relative_to = "camera" }\n'))
    world = scene_render_keys(spec_with(tmp_path / "c", env='key_light = { relative_to = "world" }\n'))
    assert riding == default
    assert all(world["white", yaw] != default["white", yaw] and world["studio", yaw] == default["studio", yaw]
               for yaw in (0, 45))
    assert "relative_to" not in KeyLightSpec().key_part() and KeyLightSpec(relative_to="world").key_part()["relative_to"] == "world"


# -- geometry ---------------------------------------------------------------------------------

@pytest.mark.parametrize(("azimuth", "elevation"), [(0.0, 20.0), (130.0, -35.0), (-70.0, 89.0)])
def test_camera_relative_angles_are_the_cameras_frame(azimuth: float, elevation: float) -> None:
    state = SceneState(azimuth=azimuth, elevation=elevation)
    position, right, up, _ = state.camera_basis()
    toward_camera = position / np.linalg.norm(position)
    assert np.allclose(direction(state, 0, 0, "camera"), toward_camera)
    assert np.allclose(direction(state, 90, 0, "camera"), right)  # azimuth > 0: the image's right
    assert np.allclose(direction(state, -90, 0, "camera"), -right)
    assert np.allclose(direction(state, 0, 90, "camera"), up)  # elevation > 0: the image's top
    assert np.allclose(direction(state, 0, 0, "world"), [0, -1, 0])  # world: in front, whatever the camera


def test_world_and_camera_angles_agree_for_a_camera_in_front_at_the_horizon() -> None:
    state = SceneState(azimuth=0.0, elevation=0.0)
    for az, el in [(40, 45), (-120, 10), (180, -60)]:
        assert np.allclose(direction(state, az, el, "camera"), direction(state, az, el, "world"))


def test_a_light_faces_the_object() -> None:
    d = direction(SceneState(azimuth=33, elevation=70), 20, 80, "camera")
    rotation = facing(d)
    assert np.allclose(rotation.T @ rotation, np.eye(3)) and np.isclose(np.linalg.det(rotation), 1.0)
    assert np.allclose(rotation @ [0, 0, -1], -d)  # Blender's lights shine along local -Z


def test_temperature_zero_is_white_and_6500_kelvin_is_not() -> None:
    assert light_colour(0) == (1.0, 1.0, 1.0)
    r, g, b = kelvin_to_rgb(6500)
    assert r == 1.0 and b < 0.97  # a faint warm tint: why 0, not 6500, means white


# -- renders ----------------------------------------------------------------------------------



@pytest.fixture(scope="module")
def sphere(tmp_path_factory) -> str:
    return sphere_obj(tmp_path_factory.mktemp("sphere") / "sphere.obj")




def object_pixels(scene, mesh: str, env: EnvironmentRef, controls, **camera) -> tuple[np.ndarray, np.ndarray]:
    """(image on a white background, mask of the object's pixels): a plain colour is composited
    after rendering, so the pixels that do not change with it are the object's."""
    on_white = render(scene, mesh, replace(env, color=(1.0, 1.0, 1.0)), controls, **camera)
    on_black = render(scene, mesh, replace(env, color=(0.0, 0.0, 0.0)), controls, **camera)
    return on_white, np.abs(on_white - on_black).max(axis=2) < 1e-3


def left_minus_right(scene, mesh: str, env: EnvironmentRef, controls, **camera) -> float:
    """Mean brightness of the object's left half minus its right half, in the image."""
    image, mask = object_pixels(scene, mesh, env, controls, **camera)
    grey, half = image.mean(axis=2), image.shape[1] // 2
    return float(grey[:, :half][mask[:, :half]].mean() - grey[:, half:][mask[:, half:]].mean())


DIM = EnvironmentRef(color=(1.0, 1.0, 1.0), strength=0.2)  # little world light: the sun decides the sides


@pytest.mark.parametrize("camera", [{"azimuth": 0.0}, {"azimuth": 180.0}, {"azimuth": 90.0, "elevation": 60.0}])
def test_a_camera_relative_light_keeps_its_side_of_the_image(blender_scene, sphere, camera) -> None:
    left = [("sun_light", {"strength": 2.0, "azimuth": -90.0, "elevation": 0.0, "relative_to": "camera"})]
    assert left_minus_right(blender_scene, sphere, DIM, left, **camera) > 0.1


def test_a_world_light_stays_put_while_the_camera_goes_round(blender_scene, sphere) -> None:
    west = [("sun_light", {"strength": 2.0, "azimuth": -90.0, "elevation": 0.0})]  # the -X side
    assert left_minus_right(blender_scene, sphere, DIM, west, azimuth=0.0) > 0.1  # -X is the front camera's left
    assert left_minus_right(blender_scene, sphere, DIM, west, azimuth=180.0) < -0.1  # and the back camera's right


@pytest.mark.parametrize("relative_to", ["camera", "world"])
def test_a_world_key_light_stays_put_and_a_camera_one_rides_along(blender_scene, sphere, relative_to) -> None:
    """A key light on the -X side (world) or the image's left (camera): turning the camera to the
    back moves the lit side across the image for the world's light only."""
    key = KeyLightSpec(strength=4.0, azimuth=-90.0, elevation=0.0, fill=0.05, relative_to=relative_to)
    env = EnvironmentRef(color=(1.0, 1.0, 1.0), key_light=key)
    front, back = (left_minus_right(blender_scene, sphere, env, [], azimuth=a) for a in (0.0, 180.0))
    assert front > 0.1  # azimuth -90 is the front camera's left, in both frames
    assert back < -0.1 if relative_to == "world" else back > 0.1


def test_an_area_light_lights_its_side_and_its_size_changes_the_image(blender_scene, sphere) -> None:
    def area(size: float) -> list[tuple[str, dict]]:
        return [("area_light", {"watts": 300.0, "size": size, "azimuth": 90.0, "elevation": 0.0,
                                "relative_to": "camera", "shape": "disk"})]

    assert left_minus_right(blender_scene, sphere, DIM, area(0.5)) < -0.1  # azimuth 90: the image's right
    cube = blender_scene.cube
    small, big = (render(blender_scene, cube, DIM, area(s) + [("pin_to_ground", {"enabled": True})]) for s in (0.1, 6.0))
    assert np.abs(small - big).mean() > 0.005


def test_the_default_key_light_keeps_an_object_on_white_from_washing_out(blender_scene, sphere) -> None:
    flat, flat_mask = object_pixels(blender_scene, sphere, EnvironmentRef(color=(1.0, 1.0, 1.0)), [])
    keyed, keyed_mask = object_pixels(blender_scene, sphere, EnvironmentRef(color=(1.0, 1.0, 1.0),
                                                                            key_light=KeyLightSpec()), [])
    flat_grey, keyed_grey = flat.mean(axis=2)[flat_mask], keyed.mean(axis=2)[keyed_mask]
    assert flat_grey.std() < 0.02  # lit from everywhere alike: one flat tone
    assert keyed_grey.std() > 5 * flat_grey.std() + 0.05
    assert np.percentile(keyed_grey, 10) < flat_grey.mean() - 0.15  # a shaded side that reads against white


def test_a_white_light_renders_grey_and_6500_kelvin_warm(blender_scene, sphere) -> None:
    dark = EnvironmentRef(color=(1.0, 1.0, 1.0), strength=1e-6)

    def brightest(temperature: float) -> np.ndarray:
        lit = [("sun_light", {"strength": 2.0, "azimuth": 0.0, "elevation": 0.0, "relative_to": "camera",
                              "temperature": temperature})]
        image, mask = object_pixels(blender_scene, sphere, dark, lit)
        return image[mask].max(axis=0) * 255

    white, warm = brightest(0.0), brightest(6500.0)
    assert np.ptp(white) < 1.0
    assert warm[0] - warm[2] >= 2.0
