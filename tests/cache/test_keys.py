"""Cache keys: the canonical form (sweep3d.cache.hashing), periodic controls, and plan-level key properties."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from sweep3d.cache.hashing import canonical, digest, file_digest, files_digest
from sweep3d.core.control import wrap_periodic
from sweep3d.stages.render.controls import Camera, Orientation
from tests.helpers import examples, load_spec, plan_for, spec_toml, write_spec

FAST = settings(max_examples=examples(150), deadline=None, suppress_health_check=[HealthCheck.too_slow])

finite = st.floats(allow_nan=False, allow_infinity=False)
leaves = st.one_of(finite, st.integers(), st.text(max_size=8), st.booleans(), st.none())
flat_values = st.one_of(leaves, st.lists(leaves, max_size=4))
flat_dicts = st.dictionaries(st.text(max_size=6), flat_values, max_size=6)
nested = st.recursive(
    leaves,
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3),
    max_leaves=12,
)


def typed(value):
    """A comparable form that keeps types apart (1, 1.0 and True differ) and folds -0.0 into 0.0."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return (type(value).__name__, value)
    if isinstance(value, int):
        return ("int", value)
    if isinstance(value, float):
        return ("float", value + 0.0)
    if isinstance(value, dict):
        return ("dict", tuple(sorted((k, typed(v)) for k, v in value.items())))
    return ("list", tuple(typed(v) for v in value))


# -- canonical form --------------------------------------------------------------------------


@FAST
@given(flat_dicts, st.randoms(use_true_random=False))
def test_canonical_form_ignores_key_order(value, rnd):
    items = list(value.items())
    rnd.shuffle(items)
    shuffled = dict(items)
    assert canonical(shuffled) == canonical(value)
    assert digest(shuffled) == digest(value)


@FAST
@given(nested)
def test_nested_key_order_is_ignored(value):
    def reverse(v):
        if isinstance(v, dict):
            return {k: reverse(v[k]) for k in reversed(list(v))}
        if isinstance(v, list):
            return [reverse(x) for x in v]
        return v

    assert digest(reverse(value)) == digest(value)


def test_negative_zero_hashes_like_zero():
    assert digest({"yaw": -0.0}) == digest({"yaw": 0.0})
    assert digest([{"a": [-0.0]}]) == digest([{"a": [0.0]}])
    assert digest(-0.0) != digest(0)  # still a float, not an int


@pytest.mark.parametrize(
    "a, b",
    [(1, 1.0), (True, 1), (False, 0), (0, 0.0), ("1", 1), ("1.0", 1.0), (None, 0), ([1], 1), ([], {}), (None, "null")],
)
def test_types_are_kept_apart(a, b):
    assert digest({"x": a}) != digest({"x": b})
    assert digest([a]) != digest([b])


def test_a_float_never_looks_like_a_mapping():
    """Floats are tagged in the canonical form; a user mapping must not be able to forge that tag."""
    for x in (1.0, 0.5, -3.25):
        forged = [{"f": repr(x)}, {"$f": repr(x)}, {"$$f": repr(x)}]
        assert len({digest(x), *(digest(v) for v in forged)}) == 1 + len(forged)


def test_numpy_scalars_hash_like_python_scalars():
    assert digest({"a": np.float32(0.5), "b": np.int64(3), "c": np.bool_(True)}) == digest(
        {"a": 0.5, "b": 3, "c": True}
    )


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, np.float64("nan")])
def test_non_finite_numbers_are_refused(bad):
    with pytest.raises(ValueError, match="non-finite"):
        canonical(bad)
    with pytest.raises(ValueError):
        digest({"outer": [1, {"inner": bad}]})


@pytest.mark.parametrize("bad", [{1: "a"}, {"a": object()}, {"a": {1, 2}}])
def test_unhashable_values_are_refused(bad):
    with pytest.raises(TypeError):
        digest(bad)


@FAST
@given(nested, nested)
def test_different_values_have_different_canonical_forms(a, b):
    if typed(a) != typed(b):
        assert canonical(a) != canonical(b)
        assert digest(a) != digest(b)
    else:
        assert digest(a) == digest(b)


@FAST
@given(flat_dicts, flat_dicts)
def test_different_canonical_texts_give_different_digests(a, b):
    assert (canonical(a) == canonical(b)) == (digest(a) == digest(b))


@FAST
@given(flat_dicts.filter(bool), st.data())
def test_changing_one_leaf_changes_the_digest(value, data):
    key = data.draw(st.sampled_from(sorted(value)))
    new = data.draw(flat_values)
    assume(typed(new) != typed(value[key]))
    mutated = {**value, key: new}
    assert digest(mutated) != digest(value)


@FAST
@given(flat_dicts.filter(bool), st.data())
def test_adding_or_renaming_a_key_changes_the_digest(value, data):
    key = data.draw(st.sampled_from(sorted(value)))
    assume(key + "_" not in value and "extra_key" not in value)
    renamed = dict(value)
    renamed[key + "_"] = renamed.pop(key)
    assert digest(renamed) != digest(value)
    assert digest({**value, "extra_key": None}) != digest(value)


def test_file_digest_follows_content(tmp_path):
    a = tmp_path / "a.bin"
    a.write_bytes(b"one")
    first = file_digest(a)
    b = tmp_path / "b.bin"
    b.write_bytes(b"one")
    assert file_digest(b) == first  # content, not path
    a.write_bytes(b"two!")  # a different size, so the memo cannot serve the old digest
    assert file_digest(a) != first
    assert files_digest([a, b]) == files_digest([b, a])


# -- periodic parameters ---------------------------------------------------------------------

periods = st.sampled_from([360.0, 2 * math.pi, 1.0, 90.0])


@settings(max_examples=examples(300), deadline=None)
@given(st.floats(-1e9, 1e9, allow_nan=False), periods)
def test_wrap_periodic_lands_in_half_open_interval(x, period):
    y = wrap_periodic(x, period)
    assert -period / 2 < y <= period / 2
    assert math.copysign(1.0, y) == 1.0 or y != 0.0  # never -0.0


@settings(max_examples=examples(300), deadline=None)
@given(st.floats(-1e9, 1e9, allow_nan=False), periods)
def test_wrap_periodic_is_idempotent(x, period):
    y = wrap_periodic(x, period)
    assert wrap_periodic(y, period) == y


@settings(max_examples=examples(200), deadline=None)
@given(st.floats(-179.0, 179.0, allow_nan=False))
def test_wrap_periodic_keeps_in_range_values(x):
    assert wrap_periodic(x, 360.0) == pytest.approx(x, abs=1e-9)


def test_wrap_periodic_ends():
    assert wrap_periodic(-180.0, 360.0) == 180.0
    assert wrap_periodic(180.0, 360.0) == 180.0
    assert wrap_periodic(540.0, 360.0) == 180.0
    assert wrap_periodic(190.0, 360.0) == -170.0
    assert wrap_periodic(-0.0, 360.0) == 0.0 and math.copysign(1.0, wrap_periodic(-0.0, 360.0)) == 1.0


# Multiples of 1/64 up to a million are exact in binary, so x + 360k is exactly that angle.
angles = st.integers(-64 * 10**6, 64 * 10**6).map(lambda n: n / 64)


@FAST
@given(angles, st.integers(-1000, 1000))
def test_equal_angles_hash_equal_through_control_canonical(x, k):
    orientation = Orientation("orientation", "orientation")
    a = orientation.key_part({"yaw": x, "pitch": 0.0, "roll": 0.0})
    b = orientation.key_part({"yaw": x + 360.0 * k, "pitch": 0.0, "roll": 0.0})
    assert digest(a) == digest(b)


@FAST
@given(angles, angles)
def test_different_angles_hash_differently(x, y):
    assume((x - y) % 360.0 != 0.0)
    orientation = Orientation("orientation", "orientation")
    assert digest(orientation.key_part({"yaw": x})) != digest(orientation.key_part({"yaw": y}))


def test_only_periodic_params_are_wrapped():
    camera = Camera("camera", "camera")
    canon = camera.canonical({"azimuth": 370.0, "elevation": 30.0, "zoom": 400.0})
    assert canon == {"azimuth": 10.0, "elevation": 30.0, "zoom": 400.0}
    assert camera.is_identity(camera.params({"azimuth": 360.0}).model_dump())
    assert not camera.is_identity(camera.params({"zoom": 2.0}).model_dump())


# -- plan-level keys -------------------------------------------------------------------------

def plan_of(folder: Path, controls: str = "", *, seed: int = 1, samples: int = 1, workers: int = 1,
            threads: int = 0, policy: str = 'type = "grid"', model_digest: str = "model-x", objects: str = ""):
    """Write a spec into a fresh subfolder of ``folder`` and plan it (no rendering, no model load)."""
    render = {"resolution": 32, "samples": samples, "workers": workers, "threads": threads}
    body = spec_toml("keys", seed=seed, store=None, render=render, environments=("white", "grey"),
                     body=f"{textwrap.dedent(controls)}\n\n[policy]\n{policy}\n") + textwrap.dedent(objects)
    sub = folder / f"spec{len(list(folder.iterdir()))}"
    sub.mkdir()
    return plan_for(load_spec(write_spec(sub, body)), model_digest)


def keys_of(plan, which: str = "render_key") -> list[str]:
    return [getattr(job, which) for job in plan.jobs]


BLUR_AND_YAW = """
[[controls]]
type = "orientation"
yaw = [0, 90]

[[controls]]
type = "blur"
sigma = {sigma}
"""


def test_planning_is_deterministic(tmp_path):
    controls = BLUR_AND_YAW.format(sigma="[0.0, 1.0]")
    first, second = plan_of(tmp_path, controls), plan_of(tmp_path, controls)
    assert len(first.jobs) == 2 * 2 * 2
    assert first.jobs == second.jobs
    assert len(set(keys_of(first, "pred_key"))) == len(first.jobs)


def test_post_control_changes_image_and_pred_keys_only(tmp_path):
    a = plan_of(tmp_path, BLUR_AND_YAW.format(sigma="1.0"))
    b = plan_of(tmp_path, BLUR_AND_YAW.format(sigma="2.0"))
    assert keys_of(a) == keys_of(b)
    for ja, jb in zip(a.jobs, b.jobs):
        assert ja.image_key != jb.image_key
        assert ja.pred_key != jb.pred_key


def test_model_changes_only_pred_keys(tmp_path):
    controls = BLUR_AND_YAW.format(sigma="[0.0, 1.0]")
    x = plan_of(tmp_path, controls, model_digest="x")
    y = plan_of(tmp_path, controls, model_digest="y")
    assert keys_of(x) == keys_of(y)
    assert keys_of(x, "image_key") == keys_of(y, "image_key")
    assert all(px != py for px, py in zip(keys_of(x, "pred_key"), keys_of(y, "pred_key")))


def test_identity_post_control_keeps_image_key_equal_to_render_key(tmp_path):
    plan = plan_of(tmp_path, BLUR_AND_YAW.format(sigma="[0.0, 1.0]"))
    for job in plan.jobs:
        blurred = job.values["blur"]["sigma"] != 0.0
        assert (job.image_key != job.render_key) == blurred


def test_neutral_control_is_dropped_from_the_key(tmp_path):
    without = plan_of(tmp_path, "")
    neutral = plan_of(tmp_path, '[[controls]]\ntype = "orientation"\nyaw = 0\n')
    turned = plan_of(tmp_path, '[[controls]]\ntype = "orientation"\nyaw = 10\n')
    assert keys_of(without) == keys_of(neutral)
    assert keys_of(without, "pred_key") == keys_of(neutral, "pred_key")
    assert all(a != b for a, b in zip(keys_of(without), keys_of(turned)))


def test_neutral_stochastic_control_does_not_add_the_seed(tmp_path):
    blur = '[[controls]]\ntype = "blur"\nsigma = 1.0\n'
    noise0 = '[[controls]]\ntype = "noise"\nstd = 0.0\n'
    noise = '[[controls]]\ntype = "noise"\nstd = 0.1\n'
    assert keys_of(plan_of(tmp_path, blur), "image_key") == keys_of(plan_of(tmp_path, blur + noise0), "image_key")
    assert keys_of(plan_of(tmp_path, blur + noise0, seed=1), "image_key") == keys_of(
        plan_of(tmp_path, blur + noise0, seed=2), "image_key"
    )
    # a noise that does something is seeded, so the experiment seed is part of its key
    assert keys_of(plan_of(tmp_path, noise, seed=1), "image_key") != keys_of(
        plan_of(tmp_path, noise, seed=2), "image_key"
    )


def test_angles_a_turn_apart_render_once(tmp_path):
    yaw = '[[controls]]\ntype = "orientation"\nyaw = {}\n'
    assert keys_of(plan_of(tmp_path, yaw.format(370))) == keys_of(plan_of(tmp_path, yaw.format(10)))
    assert keys_of(plan_of(tmp_path, yaw.format(-170))) == keys_of(plan_of(tmp_path, yaw.format(190)))
    assert keys_of(plan_of(tmp_path, yaw.format(10))) != keys_of(plan_of(tmp_path, yaw.format(20)))


OTHER_OBJECT = """
[[objects]]
name = "other"
mesh = "other/cube.obj"
labels = ["crate"]
"""


def test_control_restricted_to_another_object_leaves_this_one_alone(tmp_path):
    def plan(controls):
        p = plan_of(tmp_path, controls, objects=OTHER_OBJECT.replace("other/cube.obj", "cube.obj"))
        return {(j.object, j.environment): j for j in p.jobs}

    base = plan("")
    restricted = plan('[[controls]]\ntype = "blur"\nsigma = 2.0\nobjects = ["other"]\n'
                      '[[controls]]\ntype = "scale"\nfactor = 2.0\nobjects = ["other"]\n')
    assert base.keys() == restricted.keys()
    for scene, job in base.items():
        if scene[0] == "box":
            assert restricted[scene] == job
            assert restricted[scene].values == {}
        else:
            assert restricted[scene].render_key != job.render_key
            assert restricted[scene].image_key != job.image_key


def test_workers_and_threads_do_not_change_render_keys_but_samples_do(tmp_path):
    controls = BLUR_AND_YAW.format(sigma="1.0")
    base = keys_of(plan_of(tmp_path, controls))
    assert keys_of(plan_of(tmp_path, controls, workers=4, threads=2)) == base
    assert all(a != b for a, b in zip(keys_of(plan_of(tmp_path, controls, samples=2)), base))


def test_mesh_content_is_in_the_render_key(tmp_path):
    controls = BLUR_AND_YAW.format(sigma="1.0")
    a = plan_of(tmp_path, controls)
    sub = sorted(tmp_path.iterdir())[-1]
    (sub / "cube.obj").write_text((sub / "cube.obj").read_text() + "v 2 2 2\n")
    b = plan_for(load_spec(sub / "spec.toml"), "model-x")
    assert all(x != y for x, y in zip(keys_of(a), keys_of(b)))


RANDOM = 'type = "random"\nsamples = 6'
RANDOM_CONTROLS = """
[[controls]]
type = "orientation"
yaw = { range = [-180, 180] }

[[controls]]
type = "camera"
elevation = [0, 30, 60]
"""


def configurations(plan) -> list:
    return [(j.object, j.environment, j.values) for j in plan.jobs]


def test_random_policy_follows_the_seed(tmp_path):
    a = plan_of(tmp_path, RANDOM_CONTROLS, seed=11, policy=RANDOM)
    b = plan_of(tmp_path, RANDOM_CONTROLS, seed=11, policy=RANDOM)
    c = plan_of(tmp_path, RANDOM_CONTROLS, seed=12, policy=RANDOM)
    assert len(a.jobs) == 2 * 6
    assert configurations(a) == configurations(b)
    assert keys_of(a, "pred_key") == keys_of(b, "pred_key")
    assert configurations(a) != configurations(c)
    assert set(keys_of(a)).isdisjoint(keys_of(c))


def test_random_policy_draws_differ_per_scene(tmp_path):
    plan = plan_of(tmp_path, RANDOM_CONTROLS, seed=5, policy=RANDOM)
    yaws = {}
    for job in plan.jobs:
        yaws.setdefault(job.environment, []).append(job.values["orientation"]["yaw"])
    assert yaws["white"] != yaws["grey"]
    assert all(-180.0 <= y <= 180.0 for ys in yaws.values() for y in ys)


def test_out_of_frame_jobs_are_flagged_and_not_planned_for_rendering(tmp_path) -> None:
    from tests.helpers import TINY_SPEC, load_spec, plan_for, write_spec

    body = TINY_SPEC.replace("[policy]", '[[controls]]\ntype = "position"\nx = [0.0, 0.5, 3.0]\n\n[policy]')
    plan = plan_for(load_spec(write_spec(tmp_path, body)), "m")
    assert len(plan.jobs) == 16 and len(plan.out_of_frame) == 8
    assert all(j.values["position"]["x"] == 3.0 for j in plan.out_of_frame)
    rows = plan.rows()
    assert [r["job"] for r in rows] == list(range(24))
    assert sum(not r["in_frame"] for r in rows) == 8
