"""The Mitsuba engine (``[render] engine = "mitsuba"``): keys, refusals (fast), and renders made by
both engines in real worker processes at 32–48 px that must agree (world map orientation and
strength on an empty scene, a mesh's mask and depth), and a cached Mitsuba render kept."""

from __future__ import annotations

import io
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.core.truth import decode_mask
from sweep3d.runner import builtin_catalogue
from sweep3d.spec.models import KeyLightSpec
from sweep3d.stages.render import engine_key
from sweep3d.stages.render.mitsuba.backend import mitsuba_version
from sweep3d.stages.render.render_keys import scene_key
from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderJob, RenderSettings
from tests.helpers import TINY_SPEC, load_spec, plan_for, scene_render_keys, write_cube, write_spec

CONTROLS = builtin_catalogue().controls


def spec_with(folder: Path, render: str = "", extra: str = "") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    body = TINY_SPEC.replace("denoise = false\n", f"denoise = false\n{render}", 1)
    return write_spec(folder, body + extra)


# -- keys and refusals (no rendering) ------------------------------------------------------------

def test_the_engine_keys_mitsuba_apart_and_cycles_as_before(tmp_path: Path) -> None:
    default = scene_render_keys(spec_with(tmp_path / "a"))
    cycles = scene_render_keys(spec_with(tmp_path / "b", 'engine = "cycles"\n'))
    mitsuba = scene_render_keys(spec_with(tmp_path / "c", 'engine = "mitsuba"\n'))
    assert cycles == default  # naming the default changes no key
    assert set(mitsuba) == set(default) and not set(mitsuba.values()) & set(default.values())
    assert len(set(mitsuba.values())) == len(mitsuba)
    # Cycles' scene key is the recipe from before engines existed; Mitsuba's names its version
    settings, env = {"resolution": 32}, {"hdri": None, "color": [1.0, 1.0, 1.0], "strength": 1.0}
    assert scene_key("4.5", settings, "obj", env) == scene_key("4.5", settings, "obj", env, None, engine_key("cycles"))
    key = engine_key("mitsuba")
    assert key is not None and key["version"] == mitsuba_version() != ""
    assert scene_key("4.5", settings, "obj", env, None, key) != scene_key("4.5", settings, "obj", env)
    assert scene_key("4.4", settings, "obj", env, None, key) == scene_key("4.5", settings, "obj", env, None, key)


@pytest.mark.parametrize(("extra", "named"), [
    ('[[controls]]\ntype = "sky"\nenabled = [false, true]\n', "'sky'"),
    ('[[controls]]\ntype = "material"\nskin = ["original", "zebra"]\n', "'material'"),
    ('[[controls]]\ntype = "pin_to_ground"\nenabled = true\n', "'pin_to_ground'"),
    ('[[controls]]\ntype = "mitsuba_edits:Edits"\nwhat = 1.0\n', "'mitsuba_edits:Edits'"),
])
def test_a_control_mitsuba_cannot_render_is_refused_at_plan_in_one_line(tmp_path: Path, extra: str,
                                                                         named: str) -> None:
    for folder in (tmp_path, tmp_path / "c"):  # a user's control module beside each spec: its code
        folder.mkdir(exist_ok=True)  # identity reads this file alone, not the tests' own modules
        (folder / "mitsuba_edits.py").write_text(EDITS)
    path = spec_with(tmp_path, 'engine = "mitsuba"\n', extra)
    result = CliRunner().invoke(app, ["plan", str(path)])
    lines = result.output.strip().splitlines()
    assert result.exit_code == 2 and len(lines) == 1, result.output
    assert named in lines[0] and 'engine "mitsuba"' in lines[0] and "controls[" in lines[0]
    cycles = CliRunner().invoke(app, ["plan", str(spec_with(tmp_path / "c", "", extra))])
    assert cycles.exit_code == 0, cycles.output  # the same control is fine under Cycles


def test_mitsuba_plans_cpu_renders_and_no_uv_pass(tmp_path: Path) -> None:
    plan = plan_for(load_spec(spec_with(tmp_path / "a", 'engine = "mitsuba"\ndevice = "auto"\n')), "stand-in")
    assert plan.device == "cpu"
    path = spec_with(tmp_path / "b", 'engine = "mitsuba"\ndevice = "cuda"\n')
    result = CliRunner().invoke(app, ["plan", str(path)])
    assert result.exit_code == 2 and "render.device" in result.output and len(result.output.strip().splitlines()) == 1


#: (the ``[render]`` line, its key): Cycles-only settings away from their defaults (issue 45, item 6).
CYCLES_ONLY = [
    ("dither = 0.5\n", "render.dither"),
    ('world_sampling = "manual"\n', "render.world_sampling"),
    ("world_map_resolution = 2048\n", "render.world_map_resolution"),
    ("adaptive_threshold = 0.01\n", "render.adaptive_threshold"),
]


@pytest.mark.parametrize(("line", "key"), CYCLES_ONLY, ids=[k for _, k in CYCLES_ONLY])
def test_a_cycles_only_setting_is_refused_with_mitsuba_at_plan(tmp_path: Path, line: str, key: str) -> None:
    """A setting the engine ignores would read as applied: one line naming the key, exit 2, nothing
    written; the same spec plans under Cycles."""
    path = spec_with(tmp_path / "m", f'engine = "mitsuba"\n{line}')
    result = CliRunner().invoke(app, ["plan", str(path)])
    lines = result.output.strip().splitlines()
    assert result.exit_code == 2 and len(lines) == 1, result.output
    assert f"{path}: {key}: " in lines[0] and "is a Cycles setting" in lines[0] and 'engine "mitsuba"' in lines[0]
    assert not (tmp_path / "m" / "store").exists()
    assert CliRunner().invoke(app, ["plan", str(spec_with(tmp_path / "c", line))]).exit_code == 0


def test_a_cycles_only_setting_at_its_default_is_no_setting_for_mitsuba(tmp_path: Path) -> None:
    """Only a value that would change Cycles' image is refused: written at the default, it changes nothing."""
    path = spec_with(tmp_path, 'engine = "mitsuba"\ndither = 1.0\nworld_sampling = "automatic"\n'
                               "world_map_resolution = 1024\nadaptive_threshold = 0.0\n")
    result = CliRunner().invoke(app, ["plan", str(path)])
    assert result.exit_code == 0, result.output


def test_the_engine_spec_of_realism_score_sets_cycles_only_settings_back(tmp_path: Path) -> None:
    """``realism score --engine mitsuba`` renders a Cycles spec's picked configurations: the spec it
    writes includes the Cycles spec, whose Cycles-only settings it sets back to their defaults."""
    from sweep3d.followups.realism.score import engine_spec

    base = load_spec(spec_with(tmp_path, 'dither = 0.5\nworld_sampling = "manual"\nadaptive_threshold = 0.02\n'))
    kit = tmp_path / "kit"
    kit.mkdir()
    (kit / "design.csv").write_text("object,environment,orientation_yaw,blur_sigma\nbox,white,45.0,0.0\n")
    replay = load_spec(engine_spec(base, kit, "mitsuba"))
    plan = plan_for(replay, "stand-in")  # check_engine passes
    assert len(plan.jobs) == 1 and replay.render.engine == "mitsuba"
    assert (replay.render.dither, replay.render.world_sampling, replay.render.adaptive_threshold) == \
        (1.0, "automatic", 0.0)


#: A user's control with an ``edit``: Mitsuba has no Blender scene to edit.
EDITS = """\
from sweep3d.core.control import ControlParams
from sweep3d.stages.render.controls.rendered_control import RenderedControl


class Edits(RenderedControl):
    class Params(ControlParams):
        what: float = 0.0

    def apply(self, state, params) -> None:
        pass

    def edit(self, scene, params) -> None:
        pass
"""


def test_an_obj_reads_as_blender_imports_it(tmp_path: Path) -> None:
    """Blender's axes (OBJ's -Z forward, Y up), a concave face cut into triangles inside it, and
    the MTL's values as the importer's Principled BSDF (roughness from Ns, specular from Ks)."""
    from sweep3d.stages.render.mitsuba.objfile import read_obj

    (tmp_path / "l.mtl").write_text("newmtl red\nKd 0.5 0.1 0.1\nNs 250\nKs 0.2 0.2 0.2\nNi 1.45\nd 0.5\n")
    # an L in the OBJ's x-y plane (concave at its 4th corner: a fan from the 1st would cover the notch)
    (tmp_path / "l.obj").write_text("mtllib l.mtl\no L\nv 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\n"
                                    "usemtl red\nf 1 2 3 4 5 6\n")
    mesh = read_obj(tmp_path / "l.obj")
    (piece,) = mesh.pieces
    assert piece.object_name == "L" and piece.material == "red" and len(piece.positions) == 12
    assert np.allclose(piece.positions[:, 1], 0.0) and piece.positions[:, 2].max() == 2.0  # OBJ y is Blender z
    tris = piece.positions.reshape(-1, 3, 3)[:, :, [0, 2]]
    centroids = tris.mean(axis=1)
    assert not ((centroids[:, 0] > 1) & (centroids[:, 1] > 1)).any()  # nothing in the notch
    area = np.abs(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])).sum() / 2
    assert area == pytest.approx(3.0)
    red = mesh.materials["red"]
    assert red.roughness == pytest.approx(1 - math.sqrt(0.25)) and red.specular == pytest.approx(0.2)
    assert red.ior == 1.45 and red.opacity == 0.5 and red.base_color == (0.5, 0.1, 0.1)


def test_an_exr_s_chromaticities_are_undone_as_blender_ignores_them() -> None:
    from sweep3d.stages.render.mitsuba.hdri import REC709, rgb_to_xyz, undo_conversion

    assert undo_conversion(REC709) is None
    wide = (0.6484, 0.3309, 0.3212, 0.5979, 0.1559, 0.0661, 0.3457, 0.3585)  # the bpy wheel's city.exr
    converted = np.linalg.solve(rgb_to_xyz(REC709), rgb_to_xyz(wide))  # what Mitsuba's reader applies
    pixel = np.array([0.3, 0.5, 0.2])
    assert np.allclose(undo_conversion(wide) @ (converted @ pixel), pixel)
    assert np.allclose(rgb_to_xyz(REC709)[1].sum(), 1.0)  # white has Y = 1


# -- renders of both engines ---------------------------------------------------------------------

def _render(engine: str, jobs: list[RenderJob], size: int, samples: int, passes=()) -> dict:
    """Each job's reply from one real worker process of ``engine``."""
    from sweep3d.stages.render.pool import RenderPool

    settings = RenderSettings(resolution=size, samples=samples, denoise=False, passes=tuple(passes), engine=engine)
    with RenderPool(settings, 1) as pool:
        replies = {r.render_key: r for r in pool.run([jobs])}
    assert all(r.ok for r in replies.values()), [r.error for r in replies.values() if not r.ok]
    return replies


def _pixels(path: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"), dtype=np.float64) / 255.0


def _marked_hdri(path: Path) -> Path:
    """An equirectangular map: dim grey, a red blob at u = 0.27 just above the horizon (v = 0.46)."""
    import mitsuba as mi

    from sweep3d.stages.render.mitsuba.scene import load_mitsuba

    load_mitsuba()
    h, w = 64, 128
    v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    image = np.full((h, w, 3), 0.2, dtype=np.float32)
    blob = np.exp(-(((u - 0.27) / 0.012) ** 2 + ((v - 0.46) / 0.02) ** 2) / 2)
    image[..., 0] += 8.0 * blob.astype(np.float32)
    mi.Bitmap(image).write(str(path))
    return path


def _mark(image: np.ndarray) -> tuple[float, float]:
    """The red blob's centroid (x, y) in pixels."""
    red = np.clip(image[..., 0] - image[..., 1], 0.0, None)
    ys, xs = np.mgrid[: image.shape[0], : image.shape[1]]
    assert red.sum() > 1.0, "the mark is not in view"
    return float((xs * red).sum() / red.sum()), float((ys * red).sum() / red.sum())


@pytest.mark.blender
def test_a_marked_world_map_lands_where_cycles_puts_it_at_the_same_strength(tmp_path: Path) -> None:
    """An empty scene (the object placed far out of frame) seeing only the world: the mark lands on
    the same pixel in both engines, also turned by the hdri control, and the map's light is as
    strong (the grey's level within 5 %, and twice the strength doubles it alike)."""
    hdri = _marked_hdri(tmp_path / "marked.exr")
    cube = str(write_cube(tmp_path))
    position, camera, hdri_control = (CONTROLS.get(n)(n, n) for n in ("position", "camera", "hdri"))
    jobs = []
    for rotation, strength in ((0.0, 1.0), (10.0, 1.0), (0.0, 2.0)):
        controls = ((camera, camera.Params(elevation=0.0)), (position, position.Params(x=60.0)),
                    (hdri_control, hdri_control.Params(rotation=rotation, strength=strength)))
        key = f"{rotation}-{strength}"
        jobs.append(RenderJob(key, cube, EnvironmentRef(hdri=str(hdri)), controls))
    out = {}
    for engine in ("cycles", "mitsuba"):
        own = [replace(job, blob=str(tmp_path / f"{engine}-{job.render_key}.png")) for job in jobs]
        _render(engine, own, 48, 16)
        out[engine] = {job.render_key: _pixels(Path(job.blob)) for job in own}
    for key in ("0.0-1.0", "10.0-1.0"):
        (cx, cy), (mx, my) = _mark(out["cycles"][key]), _mark(out["mitsuba"][key])
        assert math.hypot(cx - mx, cy - my) < 1.5, (key, (cx, cy), (mx, my))
    turned, still = _mark(out["cycles"]["10.0-1.0"]), _mark(out["cycles"]["0.0-1.0"])
    assert abs(turned[0] - still[0]) > 5  # the rotation moved the mark: the test sees a wrong turn
    # the view's centre looks along +Y (u = 0.25); u = 0.27 lies toward +X, the camera's right
    assert 24 < _mark(out["cycles"]["0.0-1.0"])[0] < 40
    for key in ("0.0-1.0", "0.0-2.0"):
        grey = [np.median(out[e][key][..., 1]) for e in ("cycles", "mitsuba")]
        assert grey[1] == pytest.approx(grey[0], rel=0.05), (key, grey)


@pytest.mark.blender
def test_a_mesh_mask_and_depth_agree_with_cycles(tmp_path: Path) -> None:
    """A turned cube, plain and half hidden by the occluder: mask IoU ≥ 0.9, depth at the object's
    centre within 1 %, the visible fraction within 0.05, and the key light on a plain colour."""
    cube = str(write_cube(tmp_path))
    orientation, occlusion = CONTROLS.get("orientation")("o", "orientation"), CONTROLS.get("occlusion")("c", "occlusion")
    white = EnvironmentRef(color=(1.0, 1.0, 1.0), key_light=KeyLightSpec())
    jobs = [RenderJob("plain", cube, white, ((orientation, orientation.Params(yaw=30.0, pitch=20.0)),)),
            RenderJob("hidden", cube, white, ((orientation, orientation.Params(yaw=30.0, pitch=20.0)),
                                             (occlusion, occlusion.Params(coverage=0.5, direction=0.0))))]
    replies = {engine: _render(engine, jobs, 40, 4, ("mask", "depth")) for engine in ("cycles", "mitsuba")}
    for key in ("plain", "hidden"):
        masks = [decode_mask(replies[e][key].truth["mask"]) for e in ("cycles", "mitsuba")]
        iou = (masks[0] & masks[1]).sum() / (masks[0] | masks[1]).sum()
        assert iou >= 0.9, (key, iou)
        fractions = [replies[e][key].info.truth["visible_fraction"] for e in ("cycles", "mitsuba")]
        assert fractions[1] == pytest.approx(fractions[0], abs=0.05), (key, fractions)
    depths = [np.load(io.BytesIO(replies[e]["plain"].truth["depth"]))["depth"] for e in ("cycles", "mitsuba")]
    assert np.isfinite(depths[0][20, 20]) and depths[1][20, 20] == pytest.approx(depths[0][20, 20], rel=0.01)
    assert np.isinf(depths[1][0, 0]) and np.isinf(depths[0][0, 0])  # nothing hit in the corner
    assert replies["mitsuba"]["hidden"].info.truth["visible_fraction"] < 0.8


@pytest.mark.blender
@pytest.mark.slow
def test_a_cached_mitsuba_render_is_not_rendered_again(tmp_path: Path) -> None:
    path = spec_with(tmp_path, 'engine = "mitsuba"\n')
    first = CliRunner().invoke(app, ["run", str(path), "--no-report"])
    assert first.exit_code == 0, first.output
    from sweep3d.cache.store import Store

    store = Store(tmp_path / "store")
    before = store.table("renders").to_pylist()
    blobs = {r["render_key"]: store.blob_path(r["render_key"]).stat().st_mtime_ns for r in before}
    assert len(before) == 4
    again = CliRunner().invoke(app, ["run", str(path), "--no-report"])
    assert again.exit_code == 0, again.output
    after = Store(tmp_path / "store").table("renders").to_pylist()
    assert sorted(after, key=str) == sorted(before, key=str)
    assert {k: store.blob_path(k).stat().st_mtime_ns for k in blobs} == blobs
    cycles = CliRunner().invoke(app, ["plan", str(spec_with(tmp_path / "cycles", ""))])
    assert cycles.exit_code == 0


@pytest.mark.blender
def test_material_edits_and_parts_reach_mitsuba_s_pixels(tmp_path: Path) -> None:
    """The material control's base colour edit turns the object's pixels; a target the file lacks,
    or a part it lacks, is the user's error in Cycles' words (in-process: no Blender involved)."""
    from sweep3d.core.errors import UserError
    from sweep3d.stages.render.mitsuba.scene import MitsubaScene
    from sweep3d.stages.render.state import SceneState
    from sweep3d.stages.render.worker_protocol import Look

    (tmp_path / "two.mtl").write_text("newmtl grey\nKd 0.5 0.5 0.5\n")
    cube = write_cube(tmp_path).read_text()
    (tmp_path / "two.obj").write_text("mtllib two.mtl\no Box\nusemtl grey\n" + cube)
    scene = MitsubaScene(RenderSettings(resolution=32, samples=2, denoise=False, engine="mitsuba"), tmp_path)
    black = EnvironmentRef(color=(0.0, 0.0, 0.0))  # lit by a uniform white world, shown on black
    scene.prepare(str(tmp_path / "two.obj"), black)
    colours = {}
    for name, rgb in (("red", (0.8, 0.0, 0.0)), ("blue", (0.0, 0.0, 0.8))):
        scene.pose_scene(SceneState(yaw=30.0, material_edits=(("grey", (("base_color", rgb),)),)))
        image = scene.render()
        colours[name] = image[12:20, 12:20].reshape(-1, 3).mean(axis=0)
    assert colours["red"][0] > 3 * colours["red"][2] and colours["blue"][2] > 3 * colours["blue"][0]
    scene.pose_scene(SceneState(material_edits=(("gray", (("roughness", 0.1),)),)))
    with pytest.raises(UserError, match="'gray' is no material of two.obj"):
        scene.render()
    with pytest.raises(UserError, match="no object 'Bx'.*did you mean 'Box'"):
        scene.prepare(str(tmp_path / "two.obj"), black, Look(parts=("Bx",)))


@pytest.mark.parametrize("bad", ["v 1 2", "v a b c", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/x 2 3"])
def test_a_malformed_mesh_line_is_one_line_naming_the_file_and_line(tmp_path, bad: str) -> None:
    from sweep3d.core import UserError
    from sweep3d.stages.render.mitsuba.objfile import read_obj

    path = tmp_path / "bad.obj"
    path.write_text(bad + "\n")
    with pytest.raises(UserError, match=rf"bad\.obj:{len(bad.splitlines())}: cannot read"):
        read_obj(path)


def test_an_mtl_ior_below_one_is_blender_s_one_not_an_infinite_mitsuba_eta() -> None:
    from sweep3d.stages.render.mitsuba.translate import MIN_SPECULAR, principled

    for ior in (0.0, 0.5, 1.0):  # "Ni 0.000000" is common; Blender's IOR input stops at 1: no reflection
        assert principled({"ior": ior, "specular": 0.5})["bsdf"]["specular"] == MIN_SPECULAR
    assert principled({"ior": 1.5, "specular": 0.5})["bsdf"]["specular"] == pytest.approx(0.5)  # Blender's default
    assert principled({"ior": 1e6, "specular": 1.0})["bsdf"]["specular"] < 12.5  # never Mitsuba's infinite eta
