"""``[[objects]] parts``, ``material``/``materials`` overrides and ``auto_smooth``: names read as
Blender names them, one-line mistakes, keys unchanged without them, and real (tiny) renders where
only the chosen part shows and each override changes the pixels."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from sweep3d.assets.mesh_names import file_names
from sweep3d.cli import app
from tests.helpers import load_spec, plan_for, spec_toml, write_spec

DIGEST = "0" * 64  # a stand-in model digest: the plan needs no model

# A red square frame around a hole, with a small green cube in the hole: selecting the frame keeps
# the whole file's bounding sphere (so both renders frame alike), and the cube's pixels go.
FRAME_MTL = "newmtl red\nKd 0.8 0.05 0.05\nnewmtl green\nKd 0.05 0.8 0.05\n"


def frame_and_gem() -> str:
    outer, inner = 1.0, 0.5
    ring = [(-outer, -outer), (outer, -outer), (outer, outer), (-outer, outer),
            (-inner, -inner), (inner, -inner), (inner, inner), (-inner, inner)]
    # OBJ's y is up (Blender's importer turns it into z): the frame stands facing the camera
    lines = ["mtllib frame.mtl", "o frame"] + [f"v {x} {y} 0" for x, y in ring] + ["usemtl red"]
    lines += ["f 1 2 6 5", "f 2 3 7 6", "f 3 4 8 7", "f 4 1 5 8"]
    s = 0.3
    cube = [(x, y, z) for z in (-s, s) for y in (-s, s) for x in (-s, s)]
    lines += ["o gem"] + [f"v {x} {y} {z}" for x, y, z in cube] + ["usemtl green"]
    quads = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    lines += ["f " + " ".join(str(8 + i) for i in q) for q in quads]
    return "\n".join(lines) + "\n"


def faceted_sphere(name: str = "ball", rings: int = 6, sides: int = 8) -> list[str]:
    """A coarse UV sphere without normals (Blender shades it flat), as OBJ lines."""
    lines = [f"o {name}", "v 0 0 1"]
    for i in range(1, rings):
        t = math.pi * i / rings
        lines += [f"v {math.sin(t) * math.cos(2 * math.pi * j / sides):.5f} "
                  f"{math.sin(t) * math.sin(2 * math.pi * j / sides):.5f} {math.cos(t):.5f}" for j in range(sides)]
    lines.append("v 0 0 -1")
    bottom = 2 + (rings - 1) * sides
    ring = lambda i, j: 2 + i * sides + j % sides  # noqa: E731
    lines += [f"f 1 {ring(0, j)} {ring(0, j + 1)}" for j in range(sides)]
    lines += [f"f {ring(i, j)} {ring(i + 1, j)} {ring(i + 1, j + 1)} {ring(i, j + 1)}"
              for i in range(rings - 2) for j in range(sides)]
    lines += [f"f {bottom} {ring(rings - 2, j + 1)} {ring(rings - 2, j)}" for j in range(sides)]
    return lines


@pytest.fixture
def meshes(tmp_path: Path) -> Path:
    (tmp_path / "frame.mtl").write_text(FRAME_MTL)
    (tmp_path / "frame.obj").write_text(frame_and_gem())
    (tmp_path / "glass.mtl").write_text("newmtl glass\nKd 0.1 0.3 0.1\nd 0.3\nNi 1.5\nPc 1.0\n")
    (tmp_path / "ball.obj").write_text("\n".join(["mtllib glass.mtl", "usemtl glass"] + faceted_sphere()) + "\n")
    return tmp_path


def looks_spec(extra: str = "") -> str:
    """The frame (its parts, materials and angles as ``extra`` says) on white, at two yaws."""
    return spec_toml("looks", objects=(), body=f"""\
[[objects]]
name = "frame"
mesh = "frame.obj"
labels = ["carton"]
{extra}

[[controls]]
type = "orientation"
yaw = [0, 90]
""")


def spec(folder: Path, extra: str = "") -> Path:
    return write_spec(folder, looks_spec(extra), cube=False)


def render_keys(path: Path) -> list[str]:
    return [j.render_key for j in plan_for(load_spec(path), DIGEST).jobs]


def one_line_error(path: Path, *args: str) -> str:
    result = CliRunner().invoke(app, ["plan", str(path), *args])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "Traceback" not in result.output, result.output
    assert str(path) in lines[0]
    return lines[0]


# -- names, as Blender 4.5 gives them ------------------------------------------------------------


def test_obj_objects_are_named_by_o_lines_groups_do_not_split_and_repeats_get_suffixes() -> None:
    text = ("v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\no orange_Cube\ng peel\nf 1 2 3\ng flesh\nusemtl b\n"
            "f 1 2 3\no empty\no\no Same\nf 1 2 3\no Same\nf 1 2 3\n")
    names = file_names(text.encode(), "bowl.obj")
    # faces before the first `o` make an object named after the file; an `o` without faces makes
    # none; a bare `o` changes nothing; `g` does not split (the importer's use_split_groups is off)
    assert names.objects == ["bowl", "orange_Cube", "Same", "Same.001"]
    assert names.materials["orange_Cube"] == {"a", "b"} and names.materials["bowl"] == {"a"}
    assert file_names(b"g one\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "x.obj").objects == ["x"]
    assert file_names(b"ply\n", "x.ply") is None  # only Blender knows: checked when a worker imports it


def test_gltf_objects_are_named_by_node_then_mesh_and_a_part_brings_its_children() -> None:
    doc = {"asset": {"version": "2.0"}, "nodes": [{"name": "bowl", "children": [1, 2]}, {"mesh": 0, "name": "orange"},
                                                  {"mesh": 1}, {"mesh": 2}, {}],
           "meshes": [{"primitives": [{"material": 0}]}, {"name": "bananaMesh", "primitives": [{"material": 1}]},
                      {"primitives": []}],
           "materials": [{"name": "peel"}, {}]}
    names = file_names(json.dumps(doc).encode(), "bowl.gltf")
    assert names.objects == ["bowl", "orange", "bananaMesh", "Mesh_2", "Node_4"]
    assert names.selected(["bowl"]) == ["bowl", "orange", "bananaMesh"]
    assert names.materials_of(names.selected(["bowl"])) == ["Material_1", "peel"]


# -- mistakes: one line naming the file, the key and the fix; exit 2 ---------------------------------


@pytest.mark.parametrize("extra, key, words", [
    ('parts = ["Frame"]', "objects[0].parts[0]", ("no object 'Frame' in frame.obj", "did you mean 'frame'?", "'gem'")),
    ('parts = ["frame", "frame"]', "objects[0].parts", ("listed twice",)),
    ("parts = []", "objects[0].parts", ("at least 1",)),
    ("material = { opcity = 1.0 }", "objects[0].material.opcity", ("unknown key", "did you mean 'opacity'?")),
    ("material = { roughness = -0.1 }", "objects[0].material.roughness", ("greater than or equal to 0", "-0.1")),
    ("material = { ior = nan }", "objects[0].material.ior", ("finite",)),
    ("material = { opacity = 1.5 }", "objects[0].material.opacity", ("less than or equal to 1",)),
    ("material = { base_color = [0.1, nan, 0.1] }", "objects[0].material.base_color", ("between 0 and 1",)),
    ("materials = { gren = { roughness = 0.2 } }", "objects[0].materials.gren",
     ("no material 'gren'", "did you mean 'green'?", "material = {...}")),
    ('parts = ["frame"]\nmaterials = { green = { roughness = 0.2 } }', "objects[0].materials.green",
     ("the rendered parts of frame.obj", "'red'")),
    ("materials = { red = { shine = 1 } }", "objects[0].materials.red.shine", ("unknown key",)),
    ("auto_smooth = -30", "objects[0].auto_smooth", ("greater than 0",)),
    ("auto_smooth = nan", "objects[0].auto_smooth", ("finite",)),
])
def test_a_bad_part_material_or_angle_is_one_line_naming_the_key(meshes: Path, extra: str, key: str,
                                                                  words: tuple[str, ...]) -> None:
    line = one_line_error(spec(meshes, extra))
    assert f": {key}: " in line, line
    for word in words:
        assert word in line, line
    assert not (meshes / "store").exists()  # refused before anything is made


# -- keys --------------------------------------------------------------------------------------------


def test_no_parts_and_no_override_keep_every_key_and_each_given_one_makes_its_own(meshes: Path) -> None:
    from sweep3d.cache.hashing import digest
    from sweep3d.stages.render.render_keys import RENDER_STAGE_VERSION, scene_key

    # the recipe without a look is the one before looks existed, byte for byte
    old = digest({"stage": "render", "v": RENDER_STAGE_VERSION, "blender": "4.5", "settings": {"samples": 1},
                  "passes": [], "object": "abc", "environment": {"color": None}})
    assert scene_key("4.5", {"samples": 1}, "abc", {"color": None}) == old
    assert scene_key("4.5", {"samples": 1}, "abc", {"color": None}, None) == old

    plain = render_keys(spec(meshes))
    assert len(set(plain)) == 2
    # empty overrides are no override
    assert render_keys(spec(meshes, "material = {}\nmaterials = { red = {} }")) == plain
    looks = {extra: render_keys(spec(meshes, extra)) for extra in (
        'parts = ["frame"]', 'parts = ["gem", "frame"]', "material = { opacity = 1.0 }", "material = { opacity = 0.5 }",
        "material = { base_color = [0.05, 0.1, 0.05] }", "materials = { red = { opacity = 1.0 } }", "auto_smooth = 40")}
    assert render_keys(spec(meshes, 'parts = ["frame", "gem"]')) == looks['parts = ["gem", "frame"]']  # order: same
    assert render_keys(spec(meshes, "auto_smooth = 40.0")) == looks["auto_smooth = 40"]
    every = [k for keys in looks.values() for k in keys] + plain
    assert len(set(every)) == len(every)  # every look is its own render; the rest of each key is kept


def test_the_render_jobs_carry_the_look(meshes: Path) -> None:
    from sweep3d.cache.store import Store
    from sweep3d.stages.render.render_stage import _groups
    from sweep3d.stages.render.worker_protocol import Look

    loaded = load_spec(spec(meshes, 'parts = ["frame"]\nmaterial = { opacity = 1 }\nauto_smooth = 30'))
    plan = plan_for(loaded, DIGEST)
    jobs = [job for group in _groups(plan, Store(loaded.store), list(plan.jobs), set()) for job in group]
    assert {job.look for job in jobs} == {Look(parts=("frame",), material=(("opacity", 1.0),), auto_smooth=30.0)}


# -- real renders (32², 1 sample) -----------------------------------------------------------------


WHITE = (1.0, 1.0, 1.0)


def render(scene, mesh: Path, look=None, **state) -> np.ndarray:
    from sweep3d.stages.render.state import SceneState
    from sweep3d.stages.render.worker_protocol import EnvironmentRef

    scene.prepare(str(mesh), EnvironmentRef(color=WHITE), look)
    scene.pose_scene(SceneState(elevation=0.0, **state))
    return scene.render()


def background(image: np.ndarray) -> np.ndarray:
    return np.all(image > 0.995, axis=-1)


@pytest.mark.blender
def test_a_part_is_the_only_mesh_rendered_and_the_camera_frames_it(blender_scene, meshes: Path) -> None:
    from sweep3d.stages.render.worker import render_job
    from sweep3d.stages.render.worker_protocol import Look, RenderJob

    mesh = meshes / "frame.obj"
    full = render(blender_scene, mesh)
    green = (full[..., 1] > 2 * full[..., 0]) & ~background(full)
    red = (full[..., 0] > 2 * full[..., 1]) & ~background(full)
    assert green.sum() > 20 and red.sum() > 100  # the gem in the hole, the frame around it

    frame = render(blender_scene, mesh, Look(parts=("frame",)))
    assert background(frame)[green].all()  # where the gem was: background
    assert np.abs(frame[red] - full[red]).mean() < 0.03  # the frame where it was (same bounding sphere)

    # through the worker's entry point, as a job of the render stage sends it
    from sweep3d.stages.render.worker_protocol import EnvironmentRef
    reply = render_job(blender_scene, RenderJob("k", str(mesh), EnvironmentRef(color=WHITE), look=Look(parts=("gem",))),
                       keep_pixels=True)
    assert reply.ok, reply.error
    gem = render(blender_scene, mesh, Look(parts=("gem",)))
    gem_pixels = ~background(gem)
    assert not (gem[..., 0] > 2 * gem[..., 1])[gem_pixels].any()  # no red: the frame is not rendered
    assert gem_pixels.sum() > 3 * green.sum()  # framed alone, the gem fills the frame

    # the file's own render is untouched by the other looks (each is its own import)
    assert np.array_equal(render(blender_scene, mesh), full)


@pytest.mark.blender
def test_material_overrides_change_the_pixels_and_leave_the_file_alone(blender_scene, meshes: Path) -> None:
    from sweep3d.stages.render.worker_protocol import Look

    ball = meshes / "ball.obj"
    translucent = render(blender_scene, ball)  # the MTL's d 0.3: Blender renders it see-through
    opaque = render(blender_scene, ball, Look(material=(("opacity", 1.0),)))
    covered = ~background(opaque)
    assert covered.sum() > 100
    assert translucent[covered].mean() > opaque[covered].mean() + 0.1  # the white background showed through

    dark = render(blender_scene, ball, Look(material=(("base_color", (0.05, 0.1, 0.05)), ("opacity", 1.0))))
    assert opaque[covered].mean() > dark[covered].mean() + 0.05

    mesh = meshes / "frame.obj"
    full = render(blender_scene, mesh)
    blue = render(blender_scene, mesh, Look(materials=(("green", (("base_color", (0.0, 0.0, 0.9)),)),)))
    changed = np.abs(blue - full).max(axis=-1) > 0.05
    gem = (full[..., 1] > 2 * full[..., 0]) & ~background(full)
    assert changed[gem].mean() > 0.9 and not changed[~gem].mean() > 0.05  # the gem's material only
    assert np.array_equal(render(blender_scene, ball), translucent)  # the file's material is as it was


@pytest.mark.blender
def test_auto_smooth_shades_a_faceted_sphere_smooth(blender_scene, meshes: Path) -> None:
    from sweep3d.stages.render.worker_protocol import Look

    ball = meshes / "ball.obj"
    opaque = Look(material=(("opacity", 1.0),))
    flat = render(blender_scene, ball, opaque, yaw=10.0)
    smooth = render(blender_scene, ball, Look(material=(("opacity", 1.0),), auto_smooth=60.0), yaw=10.0)
    sharp = render(blender_scene, ball, Look(material=(("opacity", 1.0),), auto_smooth=1.0), yaw=10.0)
    surface = ~background(flat)
    assert np.abs(smooth - flat)[surface].mean() > 0.008  # the facets' edges are smoothed away (0.016 measured)
    # below the facets' angle (45°) every edge stays sharp: flat, as without smoothing
    assert np.abs(sharp - flat)[surface].mean() < np.abs(smooth - flat)[surface].mean() / 4


@pytest.mark.blender
def test_a_part_a_ply_lacks_is_found_on_import_with_did_you_mean(blender_scene, tmp_path: Path) -> None:
    from sweep3d.core.errors import UserError
    from sweep3d.stages.render.worker_protocol import Look
    from tests.helpers import files

    ply = tmp_path / "tri.ply"
    ply.write_bytes(files.ply_binary([(0, 0, 0), (1, 0, 0), (0, 1, 0)]))
    with pytest.raises(UserError, match=r"no object 'Tri' in tri\.ply \(did you mean 'tri'\?\); its objects: 'tri'"):
        render(blender_scene, ply, Look(parts=("Tri",)))
    assert render(blender_scene, ply, Look(parts=("tri",))).shape == (32, 32, 3)


@pytest.mark.blender
def test_plan_materials_prints_what_blender_renders_and_a_render_time_mistake_is_one_line(meshes: Path) -> None:
    from tests.helpers import files

    path = spec(meshes, 'parts = ["gem"]\nmaterials = { green = { roughness = 0.25 } }')
    text = path.read_text() + '\n[[objects]]\nname = "ball"\nmesh = "ball.obj"\nlabels = ["carton"]\n'
    path.write_text(text + "material = { opacity = 1.0 }\n")
    result = CliRunner().invoke(app, ["plan", str(path), "--materials"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    rows = {line.split("│")[1].strip(): [c.strip() for c in line.split("│")[2:-1]]
            for line in result.output.splitlines() if line.count("│") > 8}
    # part, material, base_color, opacity, roughness, metallic, transmission, ior, coat
    assert set(rows) == {"gem", "ball"}  # the frame is not rendered
    assert rows["gem"][:1] == ["green"] and rows["gem"][3] == "0.25*"
    assert rows["ball"][2] == "1*"  # the MTL's d 0.3, overridden
    assert rows["ball"][7] == "0.25"  # the MTL's Pc 1.0: Blender's importer sets a quarter of it as coat

    (meshes / "tri.ply").write_bytes(files.ply_binary([(0, 0, 0), (1, 0, 0), (0, 1, 0)]))
    bad = spec(meshes, "").read_text().replace('mesh = "frame.obj"', 'mesh = "tri.ply"\nparts = ["Tri"]')
    path.write_text(bad)
    line = one_line_error(path, "--materials")
    assert ": objects[0].parts: no object 'Tri' in tri.ply (did you mean 'tri'?)" in line


@pytest.mark.blender
def test_the_part_visibility_paint_shows_only_the_parts(meshes: Path) -> None:
    from sweep3d.core.uv_cells import PARTS
    from sweep3d.stages.render.cycles.paint import paint_objects
    from sweep3d.stages.render.worker_protocol import Look

    blue = np.tile([[0.1, 0.1, 0.9]], (PARTS, 1))
    mesh = str(meshes / "frame.obj")
    whole, frame = paint_objects([(mesh, blue), (mesh, blue)], resolution=48, samples=1,
                                 looks=[None, Look(parts=("frame",))])
    centre = [decode(images[0])[22:26, 22:26] for images in (whole, frame)]  # the front view's middle
    assert centre[0][..., 2].mean() > centre[0][..., 0].mean() + 0.2  # the painted gem in the hole
    assert centre[1].min() > 0.95  # without it, the white background


def decode(png: bytes) -> np.ndarray:
    import io

    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.float32) / 255.0


@pytest.mark.blender
def test_a_worker_process_renders_the_look_and_a_missing_part_stops_the_run_in_one_line(meshes: Path) -> None:
    from sweep3d.core.pixels import decode_png
    from sweep3d.stages.render.pool import RenderPool
    from sweep3d.stages.render.render_stage import _user_error
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, Look, RenderJob, RenderSettings
    from tests.helpers import files

    (meshes / "tri.ply").write_bytes(files.ply_binary([(0, 0, 0), (1, 0, 0), (0, 1, 0)]))
    white, mesh = EnvironmentRef(color=WHITE), str(meshes / "frame.obj")
    jobs = [RenderJob("whole", mesh, white, blob=str(meshes / "whole.png")),
            RenderJob("frame", mesh, white, blob=str(meshes / "frame.png"), look=Look(parts=("frame",))),
            RenderJob("tri", str(meshes / "tri.ply"), white, look=Look(parts=("Tri",)))]
    with RenderPool(RenderSettings(resolution=32, samples=1, denoise=False), workers=1) as pool:
        replies = {reply.render_key: reply for reply in pool.run([jobs])}
    whole, frame = (decode_png(meshes / f"{k}.png") for k in ("whole", "frame"))
    gem = (whole[..., 1] > 2 * whole[..., 0]) & ~background(whole)
    assert gem.sum() > 20 and background(frame)[gem].all()
    assert not replies["tri"].ok and replies["tri"].kind == "user"

    # the render stage names the spec's key: the object's parts
    loaded = load_spec(write_spec(meshes, looks_spec('parts = ["Tri"]').replace("frame.obj", "tri.ply"),
                                  cube=False))  # loads: only Blender knows a PLY's object names
    plan = plan_for(loaded, DIGEST)
    error = _user_error(plan, plan.jobs[0], replies["tri"].error)
    assert str(error).startswith(f"{loaded.path}: objects[0].parts: no object 'Tri' in tri.ply (did you mean 'tri'?)")


@pytest.mark.blender
def test_gltf_parts_are_nodes_named_as_the_loader_reads_them(blender_scene, tmp_path: Path) -> None:
    import base64
    import struct

    from sweep3d.stages.render.worker_protocol import EnvironmentRef, Look

    data = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<3H", 0, 1, 2) + b"\0\0"
    primitive = {"attributes": {"POSITION": 0}, "indices": 1}
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"name": "bowl", "children": [1, 2]}, {"name": "orange", "mesh": 0},
                     {"mesh": 1, "translation": [2, 0, 0]}],
           "meshes": [{"primitives": [primitive]}, {"name": "bananaMesh", "primitives": [primitive]}],
           "buffers": [{"byteLength": len(data),
                        "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
           "bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                          "min": [0, 0, 0], "max": [1, 1, 0]},
                         {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}]}
    path = tmp_path / "bowl.gltf"
    path.write_text(json.dumps(doc))
    read = file_names(path.read_bytes(), path.name)
    for parts, meshes in ((("orange",), 1), (("bananaMesh",), 1), (("bowl",), 2)):
        blender_scene.prepare(str(path), EnvironmentRef(color=WHITE), Look(parts=parts))
        shown = blender_scene.objects.get((str(path), Look(parts=parts)))
        assert len(blender_scene.meshes) == meshes, parts
        assert sorted(shown.names.of(o) for o in blender_scene.meshes) == sorted(read.selected(list(parts))[-meshes:])
