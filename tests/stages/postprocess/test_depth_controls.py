"""The depth-aware post controls (fog, defocus): their optics on synthetic arrays, the camera the
postprocess stage hands them, the stage's plumbing of the depth pass (a damaged pass is rendered
again), and, on tiny real renders, that their neutral values change no pixel."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sweep3d.core.control import ControlParams
from sweep3d.core.pixels import linear_to_srgb, srgb_to_linear
from sweep3d.runner import builtin_catalogue as catalogue
from sweep3d.stages.postprocess import PostControl, apply_post
from sweep3d.stages.postprocess.apply import takes_frame
from sweep3d.stages.postprocess.depth_effects import disk_kernel, signed_coc
from sweep3d.stages.postprocess.frame import RenderFrame, frame_from_state
from tests.helpers import TINY_SPEC, examples, load_spec, plan_for, spec_toml, write_spec

CONTROLS = catalogue().controls
FOG = CONTROLS.get("fog")("fog", "fog")
DEFOCUS = CONTROLS.get("defocus")("defocus", "defocus")
RNG = np.random.default_rng(0)
SIDE = 40


def frame(depth: np.ndarray, focal_px: float = 60.0, subject: float = 3.0) -> RenderFrame:
    h, w = depth.shape
    return RenderFrame(depth=depth.astype(np.float32), mask=None, focal_length=50.0, focal_px=focal_px,
                       centre=(w / 2, h / 2), subject_distance=subject)


def apply(control: PostControl, image: np.ndarray, depth: np.ndarray, **values) -> np.ndarray:
    return control.apply(image, control.params(values), np.random.default_rng(0), frame(depth))


def texture(seed: int = 0, side: int = SIDE) -> np.ndarray:
    return np.random.default_rng(seed).random((side, side, 3)).astype(np.float32)


# -- fog ----------------------------------------------------------------------------------------
depths = st.floats(0.05, 1e4) | st.sampled_from([math.inf, math.nan, -1.0, 0.0])


@settings(max_examples=examples(60), deadline=None)
@given(density=st.floats(1e-4, 1e4), values=st.lists(depths, min_size=16, max_size=16),
       grey=st.integers(0, 255), background=st.sampled_from([0.0, 2.0, 50.0]))
def test_fog_is_koschmieders_law_in_linear_light_with_the_background_rule(density, values, grey, background) -> None:
    depth = np.array(values, dtype=np.float32).reshape(4, 4)
    image = texture(1, 4)
    out = apply(FOG, image, depth, density=density, color=f"#{grey:02x}{grey:02x}{grey:02x}",
                background_distance=background)
    assert out.shape == image.shape and out.dtype == np.float32 and np.isfinite(out).all()
    f = frame(depth)
    hit = np.isfinite(depth) & (depth > 0)
    distance = np.where(hit, np.where(hit, depth, 1) * f.ray_factor(depth.shape), background or np.inf)
    t = np.exp(-density * distance)[..., None]
    airlight = srgb_to_linear(np.full(3, grey / 255.0)).astype(np.float64)
    expected = linear_to_srgb(srgb_to_linear(image) * t + airlight * (1 - t))
    assert np.allclose(out, expected, atol=2e-6)
    if background == 0:  # no surface: at infinity, fully fogged whatever the density
        assert np.allclose(out[~hit], grey / 255.0, atol=2e-6)


def test_fog_at_zero_density_is_the_identity_and_huge_density_is_the_airlight() -> None:
    image, depth = texture(), np.full((SIDE, SIDE), 3.0)
    assert FOG.is_identity({"density": 0.0, "color": "#102030", "background_distance": 4.0})
    assert not FOG.is_identity({"density": 1e-9})
    assert apply(FOG, image, depth, density=0.0, color="#102030") is image
    assert np.array_equal(apply(FOG, image, depth, density=1e4, color="#336699"),
                          np.broadcast_to(linear_to_srgb(srgb_to_linear(np.array([0x33, 0x66, 0x99]) / 255.0)),
                                          image.shape))


def test_fog_changes_far_pixels_more_than_near_ones() -> None:
    image = np.full((8, 64, 3), 0.2, np.float32)
    depth = np.tile(np.linspace(1.0, 20.0, 64), (8, 1))
    change = np.abs(apply(FOG, image, depth, density=0.2) - image).mean(axis=(0, 2))
    assert (np.diff(change) >= 0).all() and change[-1] > 2 * change[0] > 0


# -- defocus ------------------------------------------------------------------------------------
@settings(max_examples=examples(40), deadline=None)
@given(focus=st.floats(0.1, 1e3), fstop=st.floats(1e-3, 1000.0))
def test_a_plane_at_the_focus_distance_stays_sharp(focus, fstop) -> None:
    image = texture(2)
    out = apply(DEFOCUS, image, np.full((SIDE, SIDE), focus), fstop=fstop, focus_distance=focus)
    assert np.abs(out - image).max() <= 1e-6


@settings(max_examples=examples(30), deadline=None)
@given(far=st.floats(4.0, 1e4) | st.sampled_from([math.inf, math.nan]), fstop=st.floats(0.05, 2.0),
       corner=st.tuples(st.integers(2, 20), st.integers(2, 20)), side=st.integers(4, 16))
def test_a_sharp_foreground_is_not_smeared_by_the_blurred_background(far, fstop, corner, side) -> None:
    image = texture(3)
    image[..., 0] = 0.0  # the background has no red, the foreground only red
    depth = np.full((SIDE, SIDE), far)
    inside = np.zeros((SIDE, SIDE), bool)
    inside[corner[0]:corner[0] + side, corner[1]:corner[1] + side] = True
    image[inside] = [0.9, 0.0, 0.0]
    depth[inside] = 2.0
    out = apply(DEFOCUS, image, depth, fstop=fstop, focus_distance=2.0)
    assert np.abs(out[inside] - image[inside]).max() <= 1e-6  # in focus: untouched to its edge
    assert out[~inside][:, 0].max() <= 1e-6  # no red gathered into the background's blur
    assert np.isfinite(out).all()


def test_a_blurred_foreground_spreads_over_a_sharp_background_without_blurring_it() -> None:
    image = texture(4)
    image[..., 2] = 0.0  # the background has no blue ...
    depth = np.full((SIDE, SIDE), 6.0)
    inside = np.zeros((SIDE, SIDE), bool)
    inside[14:26, 14:26] = True
    image[inside] = [0.0, 0.0, 1.0]  # ... the foreground only blue (linear 1)
    depth[inside] = 2.0
    out = apply(DEFOCUS, image, depth, fstop=0.3, focus_distance=6.0)  # radius 60·(50e-3/0.6)·(1/2-1/6) = 1.7 px
    lin, before = srgb_to_linear(out).astype(np.float64), srgb_to_linear(image).astype(np.float64)
    spread = ~inside & (lin[..., 2] > 1e-4)
    assert spread.sum() > 20  # the foreground's blur reaches over the background ...
    alpha = lin[spread, 2]  # ... as a mix with the *sharp* background under it: (1 - α) · background
    assert np.allclose(lin[spread, :2], (1 - alpha)[:, None] * before[spread, :2], atol=2e-4)
    far = np.ones((SIDE, SIDE), bool)
    far[10:30, 10:30] = False
    assert np.abs(out[far] - image[far]).max() <= 1e-6  # beyond its reach the background is untouched


@pytest.mark.parametrize("radius", [3.0, 6.0, 11.0])
def test_a_point_spreads_into_the_thin_lens_circle_of_confusion(radius) -> None:
    focus, z, focal_px = 6.0, 3.0, 60.0  # a near point over a sharp far plane (behind it, the plane would hide it)
    aperture = radius / (focal_px * (1 / z - 1 / focus))
    fstop = 50e-3 / (2 * aperture)
    image = np.zeros((48, 48, 3), np.float32)
    image[24, 24] = 1.0
    depth = np.full((48, 48), focus)
    depth[24, 24] = z
    out = srgb_to_linear(apply(DEFOCUS, image, depth, fstop=fstop, focus_distance=focus)).astype(np.float64)[..., 0]
    y, x = np.mgrid[0:48, 0:48]
    second = (out * ((x - 24) ** 2 + (y - 24) ** 2)).sum() / out.sum()
    assert math.sqrt(2 * second) == pytest.approx(radius, rel=0.1)  # a uniform disk: E[ρ²] = r² / 2


def test_defocus_neutral_and_background_rules() -> None:
    image, depth = texture(5), np.full((SIDE, SIDE), 3.0)
    depth[:, :10] = np.inf
    assert DEFOCUS.is_identity({"fstop": 0.0, "focus_distance": 7.0}) and not DEFOCUS.is_identity({"fstop": 8.0})
    assert apply(DEFOCUS, image, depth, fstop=0.0) is image
    nan = depth.copy()
    nan[:, :10] = np.nan
    assert np.array_equal(apply(DEFOCUS, image, depth, fstop=0.2), apply(DEFOCUS, image, nan, fstop=0.2))
    assert np.array_equal(apply(DEFOCUS, image, depth, fstop=0.2), apply(DEFOCUS, image, depth, fstop=0.2,
                                                                          focus_distance=3.0))  # 0: the subject
    with pytest.raises(ValueError, match="depth pass"):
        DEFOCUS.apply(image, DEFOCUS.params({"fstop": 0.2}), RNG)


@settings(max_examples=examples(40), deadline=None)
@given(st.lists(st.floats(0.01, 1e5) | st.just(math.inf), min_size=2, max_size=30), st.floats(0.1, 100.0))
def test_the_signed_blur_radius_grows_with_depth_and_is_finite(values, focus) -> None:
    depth = np.sort(np.array(values))
    coc = signed_coc(depth, focus, 100.0, 0.05)
    assert np.isfinite(coc).all() and (np.diff(coc) >= -1e-9).all()
    assert np.sign(coc[depth < focus]).max(initial=-1) <= 0 and np.sign(coc[depth > focus]).min(initial=1) >= 0


@pytest.mark.parametrize("radius", [0.2, 1.0, 2.5, 9.3])
def test_disk_kernels_sum_to_one_and_spread_as_a_disk(radius) -> None:
    kernel = disk_kernel(radius)
    assert kernel.sum() == pytest.approx(1.0) and kernel.shape[0] % 2 == 1
    assert np.allclose(kernel, kernel.T) and np.allclose(kernel, kernel[::-1])
    if radius >= 2:
        half = kernel.shape[0] // 2
        y, x = np.mgrid[-half:half + 1, -half:half + 1]
        assert math.sqrt(2 * (kernel * (x**2 + y**2)).sum()) == pytest.approx(radius, rel=0.05)


# -- the camera the stage hands over ------------------------------------------------------------
@pytest.mark.parametrize("crop", [None, 224, 223])
def test_the_frame_projects_the_object_centre_where_the_state_puts_it(crop) -> None:
    from sweep3d.stages.render.state import SceneState

    state = SceneState(azimuth=30.0, elevation=10.0, zoom=1.3, focal_length=35.0, frame_x=0.4, frame_y=-0.2)
    size = 256
    f = frame_from_state(state, size, crop, np.ones((2, 2)), None)
    position, right, up, forward = state.camera_basis()
    rel = state.object_location() - position
    z = float(rel @ forward)
    x = f.centre[0] + f.focal_px * float(rel @ right) / z
    y = f.centre[1] - f.focal_px * float(rel @ up) / z
    left = (size - (crop or size)) // 2
    assert x == pytest.approx(size / 2 * (1 + 0.4) - left) and y == pytest.approx(size / 2 * (1 + 0.2) - left)
    assert f.subject_distance == pytest.approx(float(np.linalg.norm(rel)))
    assert f.subject_distance == pytest.approx(z * math.sqrt(1 + ((x - f.centre[0]) ** 2 + (y - f.centre[1]) ** 2)
                                                             / f.focal_px ** 2))  # what ray_factor computes


# -- plug-ins: the frame argument is optional -----------------------------------------------------
class Strength(ControlParams):
    strength: float = 0.0


class OldStyle(PostControl):
    """A user's control written before frames existed: three arguments, even declaring a pass."""

    passes = ("depth",)
    Params = Strength

    def apply(self, image, params, rng):
        return image * 0.5


class NewStyle(PostControl):
    passes = ("depth",)
    Params = Strength

    def apply(self, image, params, rng, frame):
        return np.where(np.isinf(frame.depth)[..., None], 0.0, image)


def test_user_controls_get_the_frame_only_when_their_apply_takes_it() -> None:
    from sweep3d.spec.loader import ControlInstance

    assert not takes_frame(OldStyle) and takes_frame(NewStyle) and takes_frame(type(FOG))
    image, depth = texture(6), np.full((SIDE, SIDE), np.inf)
    depth[5:9, 5:9] = 2.0
    insts = [ControlInstance(control=c, spaces={}) for c in (OldStyle("old", "t:Old"), NewStyle("new", "t:New"))]
    out = apply_post(image, insts, {"old": {"strength": 1.0}, "new": {"strength": 1.0}}, "ab" * 10, frame(depth))
    assert np.allclose(out[5:9, 5:9], image[5:9, 5:9] * 0.5) and not out[0, 0].any()


def test_the_controls_ask_for_the_depth_pass_and_neutral_jobs_keep_the_render_key(tmp_path: Path) -> None:
    from sweep3d.driver.passes import needed_passes

    body = TINY_SPEC.replace('type = "blur"\nsigma = [0.0, 1.5]', 'type = "fog"\ndensity = [0.0, 0.3]')
    loaded = load_spec(write_spec(tmp_path, body))
    assert needed_passes(loaded) == ("depth", "mask")
    jobs = plan_for(loaded, "0" * 64).jobs
    for job in jobs:
        assert job.truth_key is not None
        assert (job.image_key == job.render_key) == (job.values["fog"]["density"] == 0.0)


# -- the postprocess stage's plumbing, with a stand-in render stage --------------------------------
class StandInRender:
    """The real render stage's bookkeeping (``incomplete``: a render whose truth row or pass blobs
    are missing is rendered again for its passes) with synthetic pixels: a grey image and a depth
    growing left to right, nothing hit in the last column."""

    def __new__(cls):
        from sweep3d.stages.render.render_stage import RenderStage

        class Stage(RenderStage):
            def __init__(self) -> None:
                super().__init__()
                self.made: list[str] = []  # render keys computed, in order (renders and pass-only renders)

            def compute(self, todo, plan, store):
                yield from (self._one(job, plan, store) for job in todo)

            def _one(self, job, plan, store):
                from sweep3d.cache.blobs import sha256_bytes
                from sweep3d.cache.store import DIGEST_COLUMN, atomic_write, utc_now
                from sweep3d.core.pixels import encode_png
                from sweep3d.core.truth import encode_depth, encode_mask
                from sweep3d.driver.loop import Computed

                self.made.append(job.render_key)
                side = plan.framing.size
                row = None
                if not store.blob_path(job.render_key).exists():
                    data = encode_png(np.full((side, side, 3), 0.3, np.float32))
                    atomic_write(store.blob_path(job.render_key), data)
                    row = {"render_key": job.render_key, "width": side, "height": side, "valid": True, "seconds": 0.0,
                           "created_at": utc_now(), DIGEST_COLUMN: sha256_bytes(data)}
                depth = np.tile(np.linspace(1.0, 12.0, side), (side, 1)).astype(np.float32)
                depth[:, -1] = np.inf
                blobs = {"depth.npz": encode_depth(depth), "mask.png": encode_mask(np.isfinite(depth))}
                for suffix, data in blobs.items():
                    atomic_write(store.blob_path(job.truth_key, suffix), data)
                truth = {"truth_key": job.truth_key, "render_key": job.render_key, "passes": ["depth", "mask"],
                         "mask_sha256": sha256_bytes(blobs["mask.png"]), "depth_sha256": sha256_bytes(blobs["depth.npz"]),
                         "created_at": utc_now()}
                return Computed(job.render_key, row, {"truths": truth})

        return Stage()


FOG_SPEC = TINY_SPEC.replace('type = "blur"\nsigma = [0.0, 1.5]', 'type = "fog"\ndensity = [0.0, 0.3]\ncolor = "#ffffff"')


def _run(spec: Path, render) -> tuple[list, object]:
    from sweep3d.cache.store import Store
    from sweep3d.driver.loop import run_stages
    from sweep3d.driver.progress import RunProgress
    from sweep3d.stages.postprocess import PostprocessStage

    plan = plan_for(load_spec(spec), "0" * 64)
    store = Store(spec.parent / "store")
    with store.lock():
        outcomes = run_stages([render, PostprocessStage()], plan, store, RunProgress(None), overlap=True)
    return outcomes, plan


def test_the_stage_hands_the_depth_pass_over_and_renders_a_damaged_one_again(tmp_path: Path) -> None:
    from sweep3d.cache.store import Store
    from sweep3d.core.pixels import decode_png
    from sweep3d.core.truth import encode_depth

    spec = write_spec(tmp_path, FOG_SPEC)
    render = StandInRender()
    outcomes, plan = _run(spec, render)
    assert [o.computed for o in outcomes] == [4, 4] and len(render.made) == 4
    store = Store(tmp_path / "store")
    job = next(j for j in plan.jobs if j.values["fog"]["density"] > 0)
    image = decode_png(store.blob_path(job.image_key))
    change = (image - 0.3).mean(axis=(0, 2))
    assert (np.diff(change) >= 0).all() and change[15] > change[0] + 0.1  # farther: more fog (8-bit: ties at the end)
    assert change[-1] == pytest.approx(0.7, abs=1 / 255)  # nothing hit: fully fogged, white
    # a depth blob that no longer matches its digest: reported, its passes rendered again, the image made
    store.blob_path(job.truth_key, "depth.npz").write_bytes(encode_depth(np.ones((32, 32), np.float32)))
    spec.write_text(FOG_SPEC.replace("density = [0.0, 0.3]", "density = [0.0, 0.6]"))
    render = StandInRender()
    outcomes, plan = _run(spec, render)
    assert outcomes[1].repaired == 1 and outcomes[1].computed == 4 and outcomes[1].failed == 0
    assert render.made == [job.render_key]  # the passes only: its RGB blob stayed
    assert list((tmp_path / "store" / "quarantine").rglob("*.depth.npz"))  # the damaged blob is kept aside


# -- real renders ---------------------------------------------------------------------------------
REAL_SPEC = spec_toml("depth", seed=1, render={"resolution": 48, "samples": 1, "denoise": False}, body="""\
[[controls]]
type = "camera"
azimuth = 35
zoom = 1.4

[[controls]]
type = "fog"
density = [0.0, 0.4]
color = "#ff0000"

[[controls]]
type = "defocus"
fstop = [0.0, 1000.0]

[policy]
type = "grid"
""")


@pytest.mark.blender
def test_on_real_renders_neutral_values_change_no_pixel_and_fog_grows_with_distance(tmp_path: Path) -> None:
    from sweep3d.cache.blobs import load_pass
    from sweep3d.cache.store import Store
    from sweep3d.core.pixels import decode_png
    from sweep3d.stages.render.render_stage import RenderStage

    spec = write_spec(tmp_path, REAL_SPEC)
    outcomes, plan = _run(spec, RenderStage())
    assert [o.computed for o in outcomes] == [1, 3] and not any(o.failed for o in outcomes)
    store = Store(tmp_path / "store")
    jobs = {(j.values["fog"]["density"], j.values["defocus"]["fstop"]): j for j in plan.jobs}
    render = decode_png(store.blob_path(jobs[0.0, 0.0].render_key))
    assert jobs[0.0, 0.0].image_key == jobs[0.0, 0.0].render_key  # both neutral: the render is the image
    # an infinite depth of field (f/1000 here: blur radii of 1/2000 px) leaves every pixel as rendered
    assert np.array_equal(decode_png(store.blob_path(jobs[0.0, 1000.0].image_key)), render)
    depth = load_pass(store, jobs[0.0, 0.0].truth_key, "depth")
    mask = load_pass(store, jobs[0.0, 0.0].truth_key, "mask")
    assert depth.shape == render.shape[:2] and np.isfinite(depth[mask]).all() and np.isinf(depth[~mask]).all()
    from sweep3d.stages.postprocess.post_stage import job_frame

    real = job_frame(plan, jobs[0.0, 0.0], {"depth": depth})
    assert FOG.apply(render, FOG.params({"density": 0.0}), RNG, real) is render
    fogged = decode_png(store.blob_path(jobs[0.4, 1000.0].image_key))
    change = np.abs(fogged - render).mean(axis=-1)
    near, far = np.quantile(depth[mask], [1 / 3, 2 / 3])
    assert change[mask & (depth >= far)].mean() > change[mask & (depth <= near)].mean() + 0.02
    assert change[~mask].min() > change[mask].max() - 1 / 255  # no surface: fully fogged, changed most
    assert np.allclose(fogged[~mask], [1.0, 0.0, 0.0], atol=1 / 255)


def test_a_tiny_f_number_blurs_at_most_the_whole_image_without_a_huge_kernel() -> None:
    """f/0.001 would ask for a blur thousands of pixels wide; it is capped at the image's diagonal
    (wider changes nothing), so the run neither stops nor fills memory."""
    control = catalogue().controls.get("defocus")("defocus", "defocus")
    depth = np.full((48, 48), 3.0)
    depth[:, 24:] = 12.0
    image = np.random.default_rng(0).random((48, 48, 3)).astype(np.float32)
    out = control.apply(image, control.Params(fstop=0.001, focus_distance=0.5), np.random.default_rng(0),
                        frame(depth))
    assert out.shape == image.shape and np.isfinite(out).all()
    assert out.std() < image.std() / 4  # blurred to near its mean
    assert disk_kernel(300.0).shape == (601, 601) and abs(disk_kernel(300.0).sum() - 1.0) < 1e-9


def test_a_control_s_passes_do_not_change_which_results_are_counted(tmp_path: Path) -> None:
    """Fog brings the depth (and mask) pass, but only the evaluation's own passes switch
    ``evaluable`` to the visibility gate: adding fog keeps the counted results of the spec without it."""
    from sweep3d.driver.passes import visibility_gated
    from sweep3d.results.base_views import plan_min_visible
    from sweep3d.spec.columns import MIN_VISIBLE_METADATA, MIN_VISIBLE_OFF

    fog = TINY_SPEC.replace('type = "blur"\nsigma = [0.0, 1.5]', 'type = "fog"\ndensity = [0.0, 0.3]')
    for i, (body, gated) in enumerate([(fog, False), (fog.replace("[model]", '[evaluator]\npasses = ["mask"]\n\n'
                                                                             "[model]"), True)]):
        folder = tmp_path / str(i)
        folder.mkdir()
        loaded = load_spec(write_spec(folder, body))
        assert visibility_gated(loaded) is gated
        table = plan_for(loaded, "0" * 64).table()
        recorded = table.schema.metadata[MIN_VISIBLE_METADATA]
        assert (recorded == MIN_VISIBLE_OFF) is not gated
        import pyarrow.parquet as pq

        pq.write_table(table, folder / "jobs.parquet")
        assert plan_min_visible(folder / "jobs.parquet") == (None if not gated else loaded.evaluator.min_visible)
