"""Real Blender renders at tiny resolution: scene state and pixels."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sweep3d.assets.sources import builtin_hdris
from sweep3d.core.errors import UserError
from sweep3d.stages.render.controls import Camera, Orientation, Position
from sweep3d.stages.render.state import SceneState
from sweep3d.stages.render.worker_protocol import EnvironmentRef

pytestmark = pytest.mark.blender

WHITE = EnvironmentRef(color=(1.0, 1.0, 1.0))


@pytest.fixture
def scene(blender_scene):
    return blender_scene


def render(scene, state: SceneState, env=WHITE) -> np.ndarray:
    scene.prepare(scene.cube, env)
    scene.pose_scene(state)
    return scene.render()


def test_render_returns_finite_rgb_with_the_object_on_the_background(scene) -> None:
    image = render(scene, SceneState())
    assert image.shape == (32, 32, 3) and image.dtype == np.float32
    assert np.isfinite(image).all() and image.min() >= 0 and image.max() <= 1
    corners = image[[0, 0, -1, -1], [0, -1, 0, -1]]
    assert np.allclose(corners, 1.0, atol=0.02), "plain white background at the corners"
    assert image[12:20, 12:20].mean() < 0.95, "the object covers the centre"


def test_object_is_normalised_to_a_unit_sphere_at_the_origin(scene) -> None:
    render(scene, SceneState())
    points = scene._world_vertices(scene.meshes)
    centre = (points.min(axis=0) + points.max(axis=0)) / 2
    radius = np.sqrt(((points - centre) ** 2).sum(axis=1)).max()
    assert np.allclose(centre, 0, atol=1e-6) and radius == pytest.approx(1.0, rel=1e-6)


def test_camera_follows_the_state(scene) -> None:
    state = SceneState()
    Camera("camera", "camera").apply(state, Camera.Params(azimuth=90, elevation=90, zoom=2))
    render(scene, state)
    position, *_ = state.camera_basis()
    assert np.allclose(np.array(scene.camera.matrix_world.translation), position, atol=1e-5)
    assert scene.camera.data.lens == pytest.approx(50.0)


@pytest.mark.parametrize(
    "control, params",
    [
        (Orientation, {"yaw": 45.0, "pitch": 30.0}),
        (Camera, {"elevation": 80.0}),
        (Camera, {"zoom": 0.5}),
        (Position, {"x": 0.6, "y": -0.4}),
    ],
)
def test_each_control_changes_the_image(scene, control, params) -> None:
    base = render(scene, SceneState())
    state = SceneState()
    control("c", "c").apply(state, control.Params(**params))
    changed = render(scene, state)
    assert np.isfinite(changed).all()
    assert np.abs(changed - base).mean() > 0.005


def test_hdri_environment_fills_the_background(scene) -> None:
    env = EnvironmentRef(hdri=str(builtin_hdris()["forest"]))
    image = render(scene, SceneState(), env)
    assert not np.allclose(image[0, 0], 1.0, atol=0.05)
    assert scene.scene.render.film_transparent is False


def test_an_hdri_renders_blob_is_blenders_own_file_with_the_pixels_render_gives(scene) -> None:
    from sweep3d.core.pixels import decode_png, encode_png, png_size

    forest = EnvironmentRef(hdri=str(builtin_hdris()["forest"]))
    scene.prepare(scene.cube, forest)
    scene.pose_scene(SceneState(yaw=30.0))
    blob = scene.render_png()
    assert blob == scene.frame.read_bytes(), "the file Blender wrote, not decoded and encoded again"
    assert b"tEXt" not in blob, "no dates or render times: the same render gives the same bytes"
    assert blob == scene.render_png()
    assert png_size(blob) == (32, 32) and scene.scene.render.image_settings.color_mode == "RGB"
    scene.frame.write_bytes(blob)
    assert np.array_equal(decode_png(scene.frame), scene.render()), "what the old path decoded and encoded"
    scene.prepare(scene.cube, WHITE)  # a plain colour is composited behind the render: encoded by sweep3d
    scene.pose_scene(SceneState(yaw=30.0))
    assert scene.render_png() == encode_png(scene.render())
    assert scene.scene.render.image_settings.color_mode == "RGBA"


def test_pose_change_does_not_reload_the_scene(scene) -> None:
    render(scene, SceneState())
    mesh = scene.meshes[0]
    state = SceneState(yaw=90.0)
    render(scene, state)
    assert scene.meshes[0] == mesh


def test_a_mesh_without_geometry_is_a_user_error_that_leaves_the_scene_as_it_was(scene, tmp_path: Path) -> None:
    render(scene, SceneState())
    before = set(scene.bpy.data.objects)
    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing\n")
    with pytest.raises(UserError, match="no mesh"):
        scene.prepare(str(empty), WHITE)
    assert set(scene.bpy.data.objects) == before and scene.object_ref == scene.cube


def _triangle_formats(folder: Path) -> dict[str, Path]:
    """A tetrahedron in PLY, STL and glTF (buffer embedded as a data URI)."""
    import base64
    import json
    import struct

    verts = [(0, 0, 0), (2, 0, 0), (0, 2, 0), (0, 0, 2)]
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    ply = folder / "tetra.ply"
    ply.write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 4\nproperty list uchar int vertex_indices\nend_header\n"
        + "".join(f"{x} {y} {z}\n" for x, y, z in verts)
        + "".join(f"3 {a} {b} {c}\n" for a, b, c in faces)
    )
    stl = folder / "tetra.stl"
    stl.write_text(
        "solid t\n"
        + "".join(
            "facet normal 0 0 0\nouter loop\n" + "".join(f"vertex {x} {y} {z}\n" for x, y, z in (verts[i] for i in f))
            + "endloop\nendfacet\n"
            for f in faces
        )
        + "endsolid t\n"
    )
    positions = b"".join(struct.pack("<3f", *v) for v in verts)
    indices = b"".join(struct.pack("<3H", *f) for f in faces)
    data = positions + indices
    gltf = folder / "tetra.gltf"
    gltf.write_text(json.dumps({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": len(data), "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(positions)},
                        {"buffer": 0, "byteOffset": len(positions), "byteLength": len(indices)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [0, 0, 0], "max": [2, 2, 2]},
                      {"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"}],
    }))
    return {"ply": ply, "stl": stl, "gltf": gltf}


@pytest.mark.parametrize("fmt", ["ply", "stl", "gltf"])
def test_other_mesh_formats_load_and_are_normalised(scene, tmp_path: Path, fmt: str) -> None:
    path = _triangle_formats(tmp_path)[fmt]
    scene.prepare(str(path), replace(WHITE, color=(0.0, 0.0, 0.0)))  # a lit grey object on black
    scene.pose_scene(SceneState())
    image = scene.render()
    points = scene._world_vertices(scene.meshes)
    radius = np.sqrt(((points - (points.min(0) + points.max(0)) / 2) ** 2).sum(axis=1)).max()
    assert radius == pytest.approx(1.0, rel=1e-5)
    assert image.max() > 0.3 and image[0, 0].max() < 0.01, "the tetrahedron is visible on black"


@pytest.mark.parametrize("state", [
    SceneState(frame_x=0.9), SceneState(frame_x=-1.2, frame_y=0.5), SceneState(zoom=8.0, frame_x=0.5),
    SceneState(elevation=89.0, azimuth=30.0, frame_y=1.1), SceneState(scale=0.05, frame_x=0.95, frame_y=-0.95),
    SceneState(frame_x=3.0), SceneState(scale=0.1, frame_x=1.5), SceneState(frame_y=-2.0, zoom=0.5),
])
def test_out_of_frame_detection_agrees_with_the_render(scene, state) -> None:
    """The planner's geometric test says 'out of frame' exactly when the render shows no object."""
    from sweep3d.stages.render.state import in_frame

    image = render(scene, state)
    visible = bool((np.abs(image - 1.0) > 0.02).any())
    predicted = in_frame(state)
    if not predicted:
        assert not visible, "flagged out of frame, but the object shows"
    if visible:
        assert predicted


# -- a worker keeps what it has loaded ------------------------------------------------------------
def _shown(scene) -> list:
    """The meshes Cycles renders: those under the pose empty not hidden for render."""
    return [o for o in scene.pose.children_recursive if o.type == "MESH" and not o.hide_render]


def _render_mesh(scene, mesh: Path | str, state: SceneState, env=WHITE) -> np.ndarray:
    scene.prepare(str(mesh), env)
    scene.pose_scene(state)
    return scene.render()


def test_switching_objects_shows_one_and_keeps_the_others_loaded(scene, tmp_path: Path) -> None:
    tetra = _triangle_formats(tmp_path)["ply"]
    cube = render(scene, SceneState(yaw=30.0, pin_to_ground=True))
    cube_meshes = list(scene.meshes)
    other = _render_mesh(scene, tetra, SceneState(yaw=30.0, pin_to_ground=True))
    assert _shown(scene) == scene.meshes and not set(scene.meshes) & set(cube_meshes)
    assert np.abs(other - cube).mean() > 0.01
    ground = scene.props.ground.location.z
    assert ground == pytest.approx(scene._world_vertices(scene.meshes)[:, 2].min(), abs=1e-5), "pinned: this object's feet"
    again = render(scene, SceneState(yaw=30.0, pin_to_ground=True))
    assert scene.meshes == cube_meshes and _shown(scene) == cube_meshes, "shown again, not imported again"
    assert np.array_equal(again, cube), "renders are bit-identical within a process"


def test_a_skin_stays_with_its_job_not_with_the_object_it_was_on(scene, tmp_path: Path) -> None:
    tetra = _triangle_formats(tmp_path)["ply"]
    plain_tetra = _render_mesh(scene, tetra, SceneState())
    plain_cube = render(scene, SceneState())
    zebra = render(scene, SceneState(skin="zebra"))
    assert np.abs(zebra - plain_cube).mean() > 0.002
    assert np.array_equal(_render_mesh(scene, tetra, SceneState()), plain_tetra)
    assert np.array_equal(render(scene, SceneState()), plain_cube), "the cube has its own material back"


def test_each_environment_keeps_its_own_world(scene) -> None:
    forest = EnvironmentRef(hdri=str(builtin_hdris()["forest"]))
    first = render(scene, SceneState(), forest)
    world, nodes = scene.scene.world, dict(scene.world.nodes)
    render(scene, SceneState(), WHITE)
    assert scene.scene.world != world
    back = render(scene, SceneState(), forest)
    assert scene.scene.world == world and scene.world.nodes == nodes, "switched back, node tree not rebuilt"
    assert np.array_equal(back, first)


def test_hdri_rotation_and_strength_follow_the_job_across_world_switches(scene) -> None:
    forest, city = (EnvironmentRef(hdri=str(builtin_hdris()[name])) for name in ("forest", "city"))
    turned = SceneState(world_rotation=120.0, world_strength=2.0)
    base = render(scene, SceneState(), forest)
    changed = render(scene, turned, forest)
    assert np.abs(changed - base).mean() > 0.01
    render(scene, turned, city)
    assert np.array_equal(render(scene, SceneState(), forest), base)
    render(scene, SceneState(), city)
    assert np.array_equal(render(scene, turned, forest), changed)


def test_objects_beyond_the_budget_are_removed_and_skins_survive_the_purge(scene, tmp_path: Path, monkeypatch) -> None:
    tetra = _triangle_formats(tmp_path)["stl"]
    zebra = render(scene, SceneState(skin="zebra"))
    monkeypatch.setattr(scene.objects, "max_count", 1)
    _render_mesh(scene, tetra, SceneState(skin="zebra"))
    assert scene.cube not in scene.objects and len(scene.objects) == 1
    assert [o for o in scene.pose.children_recursive if o.type == "MESH"] == scene.meshes, "the others are gone"
    again = render(scene, SceneState(skin="zebra"))  # imported again; the zebra material was kept
    assert str(tetra) not in scene.objects and len(_shown(scene)) == len(scene.meshes)
    assert np.abs(again - zebra).max() <= 1.5 / 255


class _KillsTheWorker:
    """Stands in for a control: applying it kills the render worker, as the OOM killer would."""

    def apply(self, state: SceneState, params: object) -> None:
        os._exit(1)


def test_a_worker_dying_on_the_last_job_of_its_share_leaves_no_group_unrendered(tmp_path: Path) -> None:
    """The culprit fails after its retry; the groups still queued get a new worker (none waits forever)."""
    from sweep3d.stages.render.pool import RenderPool
    from sweep3d.stages.render.worker_protocol import RenderJob, RenderSettings
    from tests.helpers import write_cube

    cube = str(write_cube(tmp_path))
    fine = [RenderJob(key, cube, WHITE) for key in ("a", "b")]
    dies = RenderJob("x", cube, WHITE, controls=((_KillsTheWorker(), None),))
    with RenderPool(RenderSettings(resolution=32, samples=1, denoise=False), workers=1, timeout=120) as pool:
        replies = {reply.render_key: reply for reply in pool.run([[fine[0], dies], [fine[1]]])}
    assert replies["a"].ok and replies["b"].ok
    assert not replies["x"].ok and "render worker died" in (replies["x"].error or "")
