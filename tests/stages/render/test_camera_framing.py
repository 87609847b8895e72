"""The camera control's ``fill`` (framing by the bounding sphere's share of the frame) and its angle
conventions: the formula, the keys, the spec, the planner, and real renders (Blender, 32-64 px)."""

from __future__ import annotations

import math
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from sweep3d.core.errors import SpecError
from sweep3d.spec.framing import Framing
from sweep3d.stages.plan import make_plan
from sweep3d.stages.render.state import SceneState, fill_of_zoom, in_frame, zoom_for_fill
from sweep3d.stages.render.worker_protocol import EnvironmentRef
from tests.helpers import load_spec, render, spec_toml, sphere_obj, write_spec

SPEC = spec_toml("framing", store=None, render={"resolution": 32}, body="""\
[[controls]]
type = "camera"
{camera}

[policy]
{policy}
""")
GRID = 'type = "grid"\nsamples_per_dim = 3'


def plan(folder: Path, camera: str, policy: str = GRID, extra: str = ""):
    folder.mkdir(parents=True, exist_ok=True)
    loaded = load_spec(write_spec(folder, SPEC.format(camera=camera, policy=policy) + extra))
    return make_plan(loaded, framing=Framing.full(32), model_digest="m", blender="4.5")


# -- the formula ------------------------------------------------------------------------------

@pytest.mark.parametrize("focal", [15.0, 50.0, 200.0, 1000.0])
@pytest.mark.parametrize("fill", [0.1, 0.7, 1.0, 2.5])
def test_zoom_for_fill_inverts_the_readmes_framing_formula(focal: float, fill: float) -> None:
    zoom = zoom_for_fill(fill, focal)
    assert fill_of_zoom(zoom, focal) == pytest.approx(fill, rel=1e-12)
    state = SceneState(fill=fill, focal_length=focal)  # the distance the renderer uses
    angle = math.asin(1.0 / state.camera_distance())  # the unit sphere's angular radius
    assert math.tan(angle) / math.tan(state.half_fov()) == pytest.approx(fill, rel=1e-12)


def test_the_readmes_numbers() -> None:
    assert zoom_for_fill(0.7, 50.0) == pytest.approx(0.9018, abs=5e-5)  # the protocol's 70 %
    assert fill_of_zoom(1.0, 50.0) == pytest.approx(0.782, abs=5e-4)
    assert fill_of_zoom(1.0, 15.0) == pytest.approx(0.649, abs=5e-4)
    assert fill_of_zoom(4.0, 50.0) == 0.0  # the camera is inside the bounding sphere


def test_floats_and_arrays_give_the_same_zoom_bit_for_bit() -> None:
    fills, focals = np.linspace(0.05, 3.0, 97), np.linspace(1.0, 400.0, 97)
    many = zoom_for_fill(fills, focals)
    assert [float(z) for z in many] == [float(zoom_for_fill(float(a), float(b))) for a, b in zip(fills, focals)]


# -- keys, spec and planner -------------------------------------------------------------------

def test_a_fill_keys_as_the_zoom_it_stands_for_and_zoom_jobs_carry_no_fill(tmp_path: Path) -> None:
    zoom = float(zoom_for_fill(0.7, 85.0))
    by_fill = plan(tmp_path / "a", "fill = 0.7\nfocal_length = 85\nazimuth = [0, 90]")
    by_zoom = plan(tmp_path / "b", f"zoom = {zoom!r}\nfocal_length = 85\nazimuth = [0, 90]")
    assert [j.render_key for j in by_fill.jobs] == [j.render_key for j in by_zoom.jobs]
    assert by_fill.jobs[0].values["camera"]["fill"] == 0.7
    assert "fill" not in by_zoom.jobs[0].values["camera"]  # zoom's jobs: values (and keys) as before fill
    other = plan(tmp_path / "c", "fill = 0.7\nfocal_length = 50\nazimuth = [0, 90]")
    assert not {j.render_key for j in other.jobs} & {j.render_key for j in by_fill.jobs}  # the lens matters


def test_zoom_and_fill_together_are_one_line_naming_the_key(tmp_path: Path) -> None:
    with pytest.raises(SpecError) as caught:
        plan(tmp_path, "zoom = 1.2\nfill = 0.7")
    message = str(caught.value)
    assert "controls[0].fill" in message and "not both" in message and "\n" not in message


@pytest.mark.parametrize("policy", [GRID, 'type = "random"\nsamples = 40', 'type = "sobol"\nsamples = 32'])
def test_a_fill_range_plans_under_every_policy_with_the_in_frame_test_of_each_job(tmp_path: Path, policy) -> None:
    """Off to the side (x = 1.3), a small fill leaves the frame and a big one reaches back in."""
    p = plan(tmp_path, "fill = { range = [0.05, 1.5] }\nfocal_length = [20, 120]", policy,
             '\n[[controls]]\ntype = "position"\nx = 1.3\n')
    jobs = sorted(list(p.jobs) + list(p.out_of_frame), key=lambda j: j.index)
    outside = {j.index for j in p.out_of_frame}
    expected = {}
    for job in jobs:
        camera = job.values["camera"]
        assert 0.05 <= camera["fill"] <= 1.5
        state = SceneState(fill=camera["fill"], focal_length=camera["focal_length"], frame_x=1.3)
        expected[job.index] = in_frame(state)
    assert {i for i, inside in expected.items() if not inside} == outside
    assert outside and len(outside) < len(jobs)  # both kinds of jobs are there
    assert len({j.render_key for j in jobs}) == len({(j.values["camera"]["fill"], j.values["camera"]["focal_length"])
                                                     for j in jobs})


# -- renders ----------------------------------------------------------------------------------

@contextmanager
def frame_of(scene, pixels: int, samples: int):
    """The shared test scene at another resolution for a while."""
    render, cycles = scene.scene.render, scene.scene.cycles
    before = render.resolution_x, render.resolution_y, cycles.samples
    render.resolution_x = render.resolution_y = pixels
    cycles.samples = samples
    try:
        yield
    finally:
        render.resolution_x, render.resolution_y, cycles.samples = before


def coverage(scene, mesh: str, controls, **camera) -> np.ndarray:
    """Per pixel, how much of it the object covers (0..1): a plain background is composited after
    rendering, so on white minus on black is the background's share."""
    on_white = render(scene, mesh, EnvironmentRef(color=(1.0, 1.0, 1.0)), controls, **camera)
    on_black = render(scene, mesh, EnvironmentRef(color=(0.0, 0.0, 0.0)), controls, **camera)
    return np.clip(1.0 - (on_white - on_black).mean(axis=2), 0.0, 1.0)


@pytest.fixture(scope="module")
def fine_sphere(tmp_path_factory) -> str:
    return sphere_obj(tmp_path_factory.mktemp("sphere") / "sphere.obj", n=48)


@pytest.mark.parametrize("focal", [15.0, 200.0])
def test_a_sphere_at_fill_0_7_spans_0_7_of_the_frame(blender_scene, fine_sphere, focal: float) -> None:
    """The measured outline, from the covered area (sub-pixel), within one pixel of 70 % at a wide
    and a long lens (zoom 1 would give 65 % and 80 % there)."""
    pixels = 64
    with frame_of(blender_scene, pixels, 8):
        alpha = coverage(blender_scene, fine_sphere, [("camera", {"fill": 0.7, "focal_length": focal})])
    width = 2.0 * math.sqrt(alpha.sum() / math.pi) / pixels
    assert abs(width - 0.7) <= 1.0 / pixels, width
    assert abs(fill_of_zoom(1.0, focal) - 0.7) > 2.0 / pixels  # the test tells fill from the default zoom


def arms_obj(path: Path) -> str:
    """A cube with an arm along the file's +X and one along its +Z (a Y-up file's front): its
    bounding box's centre, where the camera looks, lies between the arms, so the heavy cube sits
    on the -X side and, in Blender (Z up, the file's +Z is -Y), on the +Y (back) side of it."""
    boxes = [((-1, -1, -1), (1, 1, 1)), ((1, -0.2, -0.2), (3, 0.2, 0.2)), ((-0.2, -0.2, 1), (0.2, 0.2, 3))]
    verts, faces = [], []
    for lo, hi in boxes:
        base = len(verts)
        verts += [(x, y, z) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
        faces += [[base + k for k in f] for f in ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6),
                                                  (0, 2, 6, 4), (1, 5, 7, 3))]
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in verts)
                    + "".join("f " + " ".join(str(k + 1) for k in f) + "\n" for f in faces))
    return str(path)


def centroid(scene, mesh: str, azimuth: float, elevation: float) -> tuple[float, float]:
    """Where the object's covered pixels centre, from the image's centre: (+ right, + up), in pixels."""
    alpha = coverage(scene, mesh, [], azimuth=azimuth, elevation=elevation, zoom=0.8)
    rows, cols = np.indices(alpha.shape)
    centre = (alpha.shape[0] - 1) / 2.0
    return float((alpha * cols).sum() / alpha.sum() - centre), float(centre - (alpha * rows).sum() / alpha.sum())


def test_the_camera_angles_are_the_readmes(blender_scene, tmp_path: Path) -> None:
    """Azimuth 0 looks at the file's front (+Z of a Y-up OBJ) with its +X on the image's right; +90 stands
    on the +X side (Blender's Right view), so positive azimuth turns counter-clockwise seen from above;
    elevation > 0 looks down from above."""
    mesh = arms_obj(tmp_path / "arms.obj")
    sides = {az: centroid(blender_scene, mesh, az, 0.0)[0] for az in (0.0, 90.0, 180.0, -90.0)}
    assert sides[0.0] < -1 and sides[90.0] > 1 and sides[180.0] > 1 and sides[-90.0] < -1
    above, below = (centroid(blender_scene, mesh, 0.0, el)[1] for el in (45.0, -45.0))
    assert above > 1 and below < -1  # the cube stands behind the centre: seen from above it is higher up
