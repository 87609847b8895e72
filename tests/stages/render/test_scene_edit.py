"""A control's ``edit`` with the live Blender scene: whatever it does is gone before the next job."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import Field

from sweep3d.core.control import ControlParams
from sweep3d.stages.render.controls.rendered_control import RenderedControl, frame_fields
from sweep3d.stages.render.worker import render_job
from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderJob
from tests.helpers import CUBE_OBJ

WHITE = EnvironmentRef(color=(1.0, 1.0, 1.0))


class Slab(RenderedControl):
    """Adds a red slab in front of the object, with a material and a modifier of its own."""

    class Params(ControlParams):
        size: float = Field(0.0, ge=0.0)

    def edit(self, scene, params) -> None:
        bpy = scene.bpy
        mesh = bpy.data.meshes.new("slab")
        s = params.size
        mesh.from_pydata([(-s, -1.5, -s), (s, -1.5, -s), (s, -1.5, s), (-s, -1.5, s)], [], [(0, 1, 2, 3)])
        material = bpy.data.materials.new("slab red")
        material.use_nodes = True
        material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (1, 0, 0, 1)
        mesh.materials.append(material)
        slab = bpy.data.objects.new("slab", mesh)
        slab.modifiers.new("thick", "SOLIDIFY")
        scene.add(slab)


class Repaint(RenderedControl):
    """Changes what the scene already holds: the object's material and a render setting."""

    class Params(ControlParams):
        on: bool = False

    def edit(self, scene, params) -> None:
        for obj in scene.objects:
            for slot in obj.material_slots:
                if slot.material is not None:
                    slot.material.diffuse_color = (0, 1, 0, 1)
        scene.scene.cycles.max_bounces = 1
        scene.objects[0].location.x += 0.3


class Broken(RenderedControl):
    """Adds an object, then raises."""

    class Params(ControlParams):
        on: bool = False

    def edit(self, scene, params) -> None:
        scene.add(scene.bpy.data.objects.new("leftover", scene.bpy.data.meshes.new("leftover")))
        raise ValueError("no liquid today")


def job(scene, tmp_path, *controls) -> RenderJob:
    return RenderJob(render_key="k", mesh=scene.cube, environment=WHITE, blob=str(tmp_path / "x.png"),
                     controls=tuple(controls), object_name="box", environment_name="white")


def pixels(reply) -> np.ndarray:
    from io import BytesIO

    from PIL import Image

    assert reply.ok, reply.error
    return np.asarray(Image.open(BytesIO(reply.png)))


@pytest.mark.blender
def test_an_edit_shows_in_its_job_and_leaves_nothing_for_the_next(blender_scene, tmp_path) -> None:
    bpy = blender_scene.bpy
    baseline = pixels(render_job(blender_scene, job(blender_scene, tmp_path), keep_pixels=True))
    counts = {name: len(getattr(bpy.data, name)) for name in ("objects", "meshes", "materials")}
    slab = Slab("slab", "tests:Slab")
    edited = render_job(blender_scene, job(blender_scene, tmp_path, (slab, slab.params({"size": 0.6}))),
                        keep_pixels=True)
    assert edited.info.rebuilt == ()
    red = pixels(edited).astype(int)
    assert ((red[..., 0] - red[..., 1]) > 100).sum() > 20, "the slab is in the edited job's render"
    after = pixels(render_job(blender_scene, job(blender_scene, tmp_path), keep_pixels=True))
    assert np.array_equal(after, baseline), "the next job renders as if the edit never ran"
    assert {name: len(getattr(bpy.data, name)) for name in counts} == counts


@pytest.mark.blender
def test_another_objects_renders_are_byte_identical_with_and_without_an_edit_on_the_first(blender_scene,
                                                                                         tmp_path) -> None:
    other = material_job(blender_scene, tmp_path, {})  # a second mesh, which the edit does not apply to
    baseline = pixels(render_job(blender_scene, other, keep_pixels=True))
    slab = Slab("slab", "tests:Slab")
    for size in (0.3, 0.6):  # the box with the slab, then the other object, twice over
        render_job(blender_scene, job(blender_scene, tmp_path, (slab, slab.params({"size": size}))), keep_pixels=True)
        assert np.array_equal(pixels(render_job(blender_scene, other, keep_pixels=True)), baseline)


@pytest.mark.blender
def test_an_edit_that_changes_held_data_rebuilds_the_scene(blender_scene, tmp_path) -> None:
    baseline = pixels(render_job(blender_scene, job(blender_scene, tmp_path), keep_pixels=True))
    repaint = Repaint("repaint", "tests:Repaint")
    reply = render_job(blender_scene, job(blender_scene, tmp_path, (repaint, repaint.params({"on": True}))),
                       keep_pixels=True)
    assert reply.ok and reply.info.rebuilt, "what it changed is reported"
    assert any("Scene" in what for what in reply.info.rebuilt)
    assert blender_scene.scene.cycles.max_bounces != 1
    after = pixels(render_job(blender_scene, job(blender_scene, tmp_path), keep_pixels=True))
    assert np.abs(after.astype(int) - baseline.astype(int)).max() <= 1


@pytest.mark.blender
def test_an_edit_that_raises_names_the_control_and_leaves_the_next_job_unchanged(blender_scene, tmp_path) -> None:
    baseline = pixels(render_job(blender_scene, job(blender_scene, tmp_path), keep_pixels=True))
    broken = Broken("broken", "tests:Broken")
    reply = render_job(blender_scene, job(blender_scene, tmp_path, (broken, broken.params({"on": True}))),
                       keep_pixels=True)
    assert not reply.ok and reply.kind == "plugin"
    assert reply.error.startswith("control 'tests:Broken' (id 'broken') (test_scene_edit.py:")
    assert "ValueError: no liquid today" in reply.error and "\n" not in reply.error
    assert "Traceback" in reply.details
    assert "leftover" not in blender_scene.bpy.data.objects
    after = pixels(render_job(blender_scene, job(blender_scene, tmp_path), keep_pixels=True))
    assert np.array_equal(after, baseline)


def test_an_edit_only_control_needs_no_state_and_moves_nothing_in_the_plan() -> None:
    slab = Slab("slab", "tests:Slab")
    assert slab.edits_scene and frame_fields(slab) == {}
    assert not RenderedControl("x", "x").edits_scene


#: The unit cube of the spec builder, as one object: its first three faces grey, the others blue.
_CUBE_LINES = CUBE_OBJ.splitlines()
TWO_MATERIALS_OBJ = "\n".join(["mtllib two.mtl", *[line for line in _CUBE_LINES if line.startswith("v ")],
                               "o box", "usemtl grey", *_CUBE_LINES[-6:-3], "usemtl blue", *_CUBE_LINES[-3:]]) + "\n"
TWO_MATERIALS_MTL = "newmtl grey\nKd 0.5 0.5 0.5\nnewmtl blue\nKd 0.1 0.2 0.8\n"


def material_job(scene, tmp_path, values: dict) -> RenderJob:
    from sweep3d.stages.render.controls import Material

    (tmp_path / "two.obj").write_text(TWO_MATERIALS_OBJ)
    (tmp_path / "two.mtl").write_text(TWO_MATERIALS_MTL)
    material = Material("material", "material")
    controls = ((material, material.params(values)),) if values else ()
    return RenderJob(render_key="k", mesh=str(tmp_path / "two.obj"), environment=WHITE,
                     blob=str(tmp_path / "x.png"), controls=controls)


@pytest.mark.blender
def test_material_edits_change_one_material_per_job_and_never_the_file(blender_scene, tmp_path) -> None:
    def render(values: dict) -> np.ndarray:
        return pixels(render_job(blender_scene, material_job(blender_scene, tmp_path, values), keep_pixels=True))

    def redness(image: np.ndarray) -> int:
        rgb = image.astype(int)
        return int(((rgb[..., 0] - rgb[..., 2]) > 80).sum())

    own = render({})
    grey_red = render({"target": "grey", "base_color": "#ff0000"})
    all_red = render({"base_color": "#ff0000"})
    assert redness(own) == 0 < redness(grey_red) < redness(all_red)
    assert not np.array_equal(render({"roughness": 0.0, "metallic": 1.0}), own)
    assert np.array_equal(render({}), own), "the file's materials are back for the next job"
    reply = render_job(blender_scene, material_job(blender_scene, tmp_path, {"target": "gray", "roughness": 0.5}))
    assert not reply.ok and reply.kind == "user"
    assert "target 'gray' is no material of two.obj (its materials: blue, grey)" in reply.error


def test_material_surface_values_leave_a_skins_key_as_it_was() -> None:
    from sweep3d.stages.render.controls import Material
    from sweep3d.stages.render.state import SceneState

    material = Material("material", "material")
    skin_only = material.key_part(material.params({"skin": "zebra"}).model_dump())
    assert skin_only == {"type": "material", "v": 2, "values": {"skin": "zebra", "scale": 1.0}}
    assert material.is_identity(material.params({}).model_dump())
    edited = material.params({"roughness": 0.25, "base_color": "#FF0000", "target": "glass"})
    assert not material.is_identity(edited.model_dump())
    assert material.key_part(edited.model_dump())["values"]["surface"] == {
        "target": "glass", "base_color": "#ff0000", "roughness": 0.25}
    state = SceneState()
    material.apply(state, edited)
    (target, pairs), = state.material_edits
    assert target == "glass" and dict(pairs)["base_color"] == pytest.approx((1.0, 0.0, 0.0))


@pytest.mark.slow
def test_a_material_target_no_object_has_is_one_line_naming_the_key(tmp_path) -> None:
    from typer.testing import CliRunner

    from sweep3d.cli import app
    from tests.helpers import TINY_SPEC, write_spec

    (tmp_path / "two.obj").write_text(TWO_MATERIALS_OBJ)
    (tmp_path / "two.mtl").write_text(TWO_MATERIALS_MTL)
    spec = write_spec(tmp_path, TINY_SPEC.replace('mesh = "cube.obj"', 'mesh = "two.obj"').replace(
        'type = "orientation"\nyaw = [0, 45]', 'type = "material"\ntarget = "gray"\nroughness = [0.2, 0.8]'))
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 2, result.output
    line = " ".join(result.output.split())
    assert "controls[0].target: the material control's target 'gray' is no material of two.obj (its materials: " \
           "blue, grey)" in line and "name one of its materials" in line, line
