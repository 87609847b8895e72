"""The Mitsuba worker's kept scene (``stages/render/mitsuba/kept.py``): a job's pixels are the same
whether the worker updates the scene it kept and replays its frozen render (``frozen.py``) or
loads the job afresh (to the last bits that Mitsuba's threads leave to chance), whatever came
before; and a sequence of jobs that change only values loads once.

In-process, 32 px and 2 samples: no Blender and no worker process."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sweep3d.spec.models import KeyLightSpec
from sweep3d.stages.render.lights import AreaLight, SunLight
from sweep3d.stages.render.mitsuba.backend import llvm_library
from sweep3d.stages.render.state import Occluder, PointLight, SceneState
from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderSettings
from tests.helpers import write_cube

pytestmark = pytest.mark.blender  # Mitsuba's JIT and renders: kept out of the fast lane with the engine's other renders

BASE = SceneState(yaw=10.0, lights=[SunLight((1.0, 1.0, 1.0), 3.0, 0.0, 30.0, 40.0, "camera")])
#: How far two renders of one job may differ: Mitsuba's film adds the overlapping borders of image
#: blocks in the order its threads finish them, so a pixel may move by a float's last bits (a
#: wrong parameter moves pixels by far more).
ULPS = 1e-6
#: The same through OpenImageDenoise, whose network carries those last bits a little further
#: (still far below an 8-bit step, 1/255).
DENOISED_ULPS = 1e-5
#: Jobs as a run's worker meets them: values change, then the structure, then values again.
STATES = [
    BASE,
    replace(BASE, yaw=75.0, pitch=10.0),
    replace(BASE, yaw=-40.0, scale=0.8, elevation=35.0, azimuth=20.0),
    replace(BASE, focal_length=35.0, world_strength=0.5),
    replace(BASE, lights=[SunLight((1.0, 0.8, 0.6), 5.0, 0.0, -60.0, 20.0, "camera")]),
    replace(BASE, material_edits=(("grey", (("base_color", (0.8, 0.1, 0.1)), ("roughness", 0.2))),)),
    replace(BASE, occluder=Occluder(0.4, 90.0)),  # a new shape: loaded afresh
    replace(BASE, occluder=Occluder(0.6, 0.0, 0.3), yaw=120.0),
    replace(BASE, lights=[PointLight((1.0, 1.0, 1.0), 200.0, 4.0, 30.0, 30.0)]),
    replace(BASE, lights=[PointLight((1.0, 1.0, 1.0), 80.0, 3.0, -30.0, 50.0)], yaw=200.0),
    replace(BASE, lights=[AreaLight((1.0, 1.0, 1.0), 100.0, 1.0, "square", 4.0, 10.0, 45.0)]),
    BASE,
]


@pytest.fixture
def mesh(tmp_path: Path) -> str:
    (tmp_path / "box.mtl").write_text("newmtl grey\nKd 0.6 0.6 0.6\n")
    (tmp_path / "box.obj").write_text("mtllib box.mtl\no Box\nusemtl grey\n" + write_cube(tmp_path).read_text())
    return str(tmp_path / "box.obj")


def _scene(tmp_path: Path, variant: str, denoise: bool = False):
    from sweep3d.stages.render.mitsuba.scene import MitsubaScene

    settings = RenderSettings(resolution=32, samples=2, denoise=denoise, engine="mitsuba", variant=variant)
    return MitsubaScene(settings, tmp_path)


#: Both variants where LLVM is present (scalar_rgb alone elsewhere).
VARIANTS = ["scalar_rgb", pytest.param("llvm_ad_rgb", marks=pytest.mark.skipif(
    llvm_library() is None, reason="no LLVM library: Mitsuba renders with scalar_rgb here"))]


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("environment", [EnvironmentRef(color=(0.2, 0.3, 0.4), key_light=KeyLightSpec()),
                                         EnvironmentRef(color=(1.0, 1.0, 1.0))], ids=["key-light", "plain"])
def test_a_job_renders_the_same_pixels_kept_or_loaded_afresh(tmp_path: Path, mesh: str,
                                                             environment: EnvironmentRef, variant: str) -> None:
    kept = _scene(tmp_path, variant)
    kept.prepare(mesh, environment)
    images = []
    for state in STATES:
        kept.pose_scene(state)
        images.append(kept.render())
    assert kept.kept.loads < len(STATES) / 2  # values changed in place, not loaded per job
    if variant != "scalar_rgb":  # the renders compared below were replayed, not traced: at most two
        # recordings per structure (the first with Dr.Jit's constants, then with what changed opaque)
        assert kept.frozen.replayed.n_recordings <= 2 * kept.kept.loads < len(STATES)
    for i in (1, 4, 5, 7, 9, 10, 11):  # each alone, in a fresh worker's scene
        fresh = _scene(tmp_path, variant)
        fresh.prepare(mesh, environment)
        fresh.pose_scene(STATES[i])
        again = fresh.render()
        assert np.abs(again - images[i]).max() <= ULPS, f"job {i} differs from its fresh render"
    assert np.abs(images[0] - images[-1]).max() <= ULPS  # the first job again, after all the others
    assert not np.array_equal(images[0], images[1]) and not np.array_equal(images[3], images[4])


@pytest.mark.skipif(llvm_library() is None, reason="no LLVM library: nothing is frozen under scalar_rgb")
def test_a_denoised_job_replayed_by_a_kept_worker_is_the_same_as_afresh(tmp_path: Path, mesh: str) -> None:
    """The denoiser's albedo and normals come along the camera's own rays (frozen.py): replayed
    after other jobs, as traced in a fresh worker."""
    environment = EnvironmentRef(color=(0.2, 0.3, 0.4), key_light=KeyLightSpec())
    kept = _scene(tmp_path, "llvm_ad_rgb", denoise=True)
    kept.prepare(mesh, environment)
    images = []
    for state in STATES[:5]:
        kept.pose_scene(state)
        images.append(kept.render())
    assert kept.kept.loads == 1 and kept.frozen.replayed.n_recordings <= 2  # the last three replayed
    for i in (2, 4):
        fresh = _scene(tmp_path, "llvm_ad_rgb", denoise=True)
        fresh.prepare(mesh, environment)
        fresh.pose_scene(STATES[i])
        assert np.abs(fresh.render() - images[i]).max() <= DENOISED_ULPS, f"job {i} differs from its fresh render"
    assert not np.array_equal(images[2], images[3])


def test_what_no_parameter_updates_loads_the_scene_again() -> None:
    """The split: floats, colours and matrices are values under Mitsuba's parameter names; types,
    sizes and flags are structure; the objects' poses apart."""
    from sweep3d.stages.render.mitsuba.kept import split

    pose = np.eye(4)
    description = {
        "type": "scene", "integrator": {"type": "path", "max_depth": 9, "hide_emitters": False},
        "sensor": {"type": "perspective", "fov": 40.0, "to_world": np.eye(4),
                   "film": {"type": "hdrfilm", "width": 32, "height": 32}},
        "object_0000": {"type": "ply", "filename": "a.ply", "to_world": pose,
                        "bsdf": {"type": "mask", "opacity": 0.5,
                                 "bsdf": {"type": "twosided", "bsdf": {"type": "principled", "roughness": 0.3,
                                                                       "base_color": {"type": "rgb",
                                                                                      "value": [0.1, 0.2, 0.3]}}}}},
    }
    parts = split(description)
    assert parts.poses == {"object_0000": pose}
    assert set(parts.values) == {"sensor.x_fov", "sensor.to_world", "object_0000.bsdf.opacity",
                                 "object_0000.bsdf.nested_bsdf.brdf_0.roughness",
                                 "object_0000.bsdf.nested_bsdf.brdf_0.base_color.value"}
    structure = dict(parts.structure)
    assert structure["integrator.max_depth"] == 9 and structure["integrator.hide_emitters"] is False
    assert structure["sensor.film.width"] == 32 and structure["object_0000.filename"] == "a.ply"


@pytest.mark.skipif(llvm_library() is None, reason="no LLVM library: nothing is traced under scalar_rgb")
def test_sweep3d_s_traced_render_is_mitsuba_s_through_a_box_filter(tmp_path: Path, mesh: str) -> None:
    """frozen.py's own loop (a pixel the mean of its samples, the aux integrator along the same
    rays) takes the samples and rays that ``mitsuba.render`` takes through a box-filtered film:
    the same pixels, crop and all."""
    from sweep3d.stages.render.mitsuba.scene import sensor_index

    scene = MitsubaSceneFactory(tmp_path)
    scene.prepare(mesh, EnvironmentRef(color=(0.2, 0.3, 0.4), key_light=KeyLightSpec()))
    scene.pose_scene(replace(BASE, yaw=60.0))
    scene.render()
    loaded, mi, aux = scene.loaded, scene.mi, scene._aux()
    camera = sensor_index(loaded, "sensor")
    # 5 samples: the multi-jittered sampler takes 6 (a 2 × 3 grid), as mitsuba.render does
    image, channels = scene.frozen(loaded, 5, 7, aux, (camera, camera), structure=hash(scene.kept.key))
    assert image.shape == (24, 24, 4) and channels is not None and channels.shape == (24, 24, 6)
    beauty = np.asarray(mi.render(loaded, sensor=camera, spp=5, seed=7), dtype=np.float32)
    albedo_normals = np.asarray(mi.render(loaded, sensor=camera, integrator=aux, spp=5, seed=7), dtype=np.float32)
    assert np.abs(image - beauty).max() <= 1e-4 * max(1.0, float(beauty.max()))
    assert np.abs(channels - albedo_normals[..., -6:]).max() <= 1e-5
    assert beauty[..., 3].min() < 0.5 < beauty[..., 3].max()  # the object and the background both in the crop


def MitsubaSceneFactory(tmp_path: Path):  # noqa: N802  (a 32² frame cropped to its centre 24²)
    from sweep3d.stages.render.mitsuba.scene import MitsubaScene

    settings = RenderSettings(resolution=32, crop=24, samples=2, denoise=True, engine="mitsuba",
                              variant="llvm_ad_rgb")
    return MitsubaScene(settings, tmp_path)


@pytest.mark.skipif(llvm_library() is None, reason="no LLVM library: nothing is frozen under scalar_rgb")
def test_a_thin_lens_renders_between_replayed_jobs_as_in_a_fresh_worker(tmp_path: Path, mesh: str) -> None:
    """A camera with an aperture (``fstop`` > 0) holds a value a frozen render cannot take as input:
    its jobs are traced each time, between pinhole jobs that are replayed, and equal a fresh worker's."""
    environment = EnvironmentRef(color=(0.2, 0.3, 0.4), key_light=KeyLightSpec())
    states = [replace(BASE, fstop=2.8), BASE, replace(BASE, fstop=2.8, yaw=50.0), replace(BASE, yaw=50.0)]
    kept = _scene(tmp_path, "llvm_ad_rgb", denoise=True)
    kept.prepare(mesh, environment)
    images = []
    for state in states:
        kept.pose_scene(state)
        images.append(kept.render())
    fresh = _scene(tmp_path, "llvm_ad_rgb", denoise=True)
    fresh.prepare(mesh, environment)
    fresh.pose_scene(states[2])
    assert np.abs(fresh.render() - images[2]).max() <= DENOISED_ULPS
    assert not np.array_equal(images[2], images[3])  # the aperture blurs what the pinhole keeps sharp
