"""The scene neighbours of ``sweep3d stability``: which parameters move and how far (at the edges
of ranges and limits), and the neighbours' plan (no render: planned with a stand-in model digest)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sweep3d.followups.stability.neighbours import Move, change_name, neighbour_value, plan_moves
from sweep3d.followups.stability.scene import neighbour_rows, scene_key, scene_order, sizes_of, variant
from sweep3d.spec import Choice, Range
from tests.helpers import examples, load_spec, plan_for, spec_toml, write_spec

finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


def _angle(space, limits=(-math.inf, math.inf), period=None, size=1.0) -> Move:
    return Move("c", "p", "angle", size, space, limits, period, "p")


@settings(max_examples=examples(300), deadline=None)
@given(st.floats(-500, 500), st.floats(0.001, 400), st.floats(0, 1), st.sampled_from([1, -1]),
       st.floats(0.01, 45))
def test_a_range_neighbour_stays_in_the_range_and_moves_at_most_one_step(low, width, u, sign, size) -> None:
    space = Range(low, low + width)
    value = space.at(u)
    got = neighbour_value(value, _angle(space, size=size), sign)
    if got is None:  # only at the edge it would cross: clipped onto the value itself
        assert value == (space.high if sign > 0 else space.low) or size == 0
        return
    assert space.low <= got <= space.high
    assert 0 < abs(got - value) <= size * (1 + 1e-9)
    assert (got - value) * sign > 0  # the direction asked: clipping never turns it around


@settings(max_examples=examples(200), deadline=None)
@given(st.floats(-180, 180), st.sampled_from([1, -1]), st.floats(0.01, 10))
def test_a_whole_turn_wraps_instead_of_clipping(value, sign, size) -> None:
    space = Range(-180.0, 180.0)
    got = neighbour_value(value, _angle(space, period=360.0, size=size), sign)
    assert got is not None and -180.0 <= got < 180.0
    turned = (got - value - sign * size) / 360.0
    assert abs(turned - round(turned)) < 1e-9  # the same direction, a whole turn at most away
    assert neighbour_value(180.0, _angle(space, period=360.0), 1) == pytest.approx(-179.0)
    assert neighbour_value(-180.0, _angle(space, period=360.0), -1) == pytest.approx(179.0)


@settings(max_examples=examples(200), deadline=None)
@given(st.sampled_from([-90.0, -89.5, 0.0, 89.5, 90.0]), st.sampled_from([1, -1]))
def test_a_list_moves_beyond_its_points_within_the_parameters_limits(value, sign) -> None:
    move = _angle(Choice((5.0, 35.0)), limits=(-90.0, 90.0))
    got = neighbour_value(value, move, sign)
    if value == 90.0 * sign:
        assert got is None  # at the limit that way: no neighbour that way
    else:
        assert got is not None and -90.0 <= got <= 90.0 and 0 < (got - value) * sign <= 1.0
    assert neighbour_value(5, move, -1) == 4 and isinstance(neighbour_value(5, move, -1), int)  # past the list's end


@settings(max_examples=examples(200), deadline=None)
@given(st.floats(1e-3, 1e3), st.sampled_from([1, -1]), st.floats(0.001, 0.5))
def test_relative_steps_are_a_share_of_the_distance_or_the_strength(value, sign, share) -> None:
    wide = Range(1e-6, 1e6, log=True)
    zoom = Move("camera", "zoom", "closeness", share, wide, (0.0, 1e6), None, "distance")
    strength = Move("hdri", "strength", "light", share, wide, (0.0, 1e6), None, "strength")
    nearer = neighbour_value(value, zoom, sign)
    assert value / nearer == pytest.approx(1 + sign * share)  # the distance (1 / zoom) by 1 ± share
    assert neighbour_value(value, strength, sign) / value == pytest.approx(1 + sign * share)
    assert change_name(zoom, sign) == f"distance{'+' if sign > 0 else '-'}{share * 100:g}%"


@given(finite, st.sampled_from([1, -1]))
def test_an_integer_range_rounds_and_never_gives_the_value_back(value, sign) -> None:
    space = Range(-1000.0, 1000.0, integer=True)
    got = neighbour_value(round(max(-1000, min(1000, value))), Move("c", "p", "light", 0.05, space), sign)
    assert got is None or (isinstance(got, int) and -1000 <= got <= 1000 and got != round(value))


def test_non_numbers_and_non_finite_values_have_no_neighbour() -> None:
    move = _angle(Range(0.0, 10.0))
    assert [neighbour_value(v, move, 1) for v in (True, "a", math.nan, math.inf)] == [None] * 4


SPEC = spec_toml("n", seed=1, objects=("box",), environments=("white", "studio"), render={
    "resolution": 32, "samples": 1, "denoise": False}, body="""\
[[controls]]
type = "orientation"
yaw = { range = [-180, 180] }
pitch = { range = [0, 30] }

[[controls]]
type = "camera"
elevation = [5, 35]
zoom = { range = [0.5, 2.0] }
focal_length = [35, 50]

[[controls]]
type = "hdri"
rotation = { range = [-180, 180] }
strength = [1.0, 2.0]

[[controls]]
type = "material"
skin = ["original", "zebra"]

[[controls]]
type = "blur"
sigma = [0.0, 1.0]

[policy]
type = "random"
samples = 6
""")


@pytest.fixture
def loaded(tmp_path: Path):
    return load_spec(write_spec(tmp_path, SPEC))


def test_every_varied_rendered_parameter_moves_or_is_listed_with_its_reason(loaded) -> None:
    moves, skipped = plan_moves(loaded.controls, sizes_of(loaded))
    got = {m.column: (m.label, m.kind, m.size) for m in moves}
    assert got == {"orientation_yaw": ("yaw", "angle", 1.0), "orientation_pitch": ("pitch", "angle", 1.0),
                   "camera_elevation": ("elevation", "angle", 1.0), "camera_zoom": ("distance", "closeness", 0.01),
                   "hdri_rotation": ("rotation", "hdri_rotation", 2.0), "hdri_strength": ("strength", "light", 0.05)}
    assert set(skipped) == {"camera_focal_length", "material_skin", "blur_sigma"}  # never silently
    assert "no invisible step" in skipped["camera_focal_length"] and "names" in skipped["material_skin"]
    assert "after rendering" in skipped["blur_sigma"]


def test_the_spec_sizes_the_steps_and_bad_sizes_are_refused(tmp_path: Path) -> None:
    from sweep3d.core import SpecError

    loaded = load_spec(write_spec(tmp_path, SPEC + "\n[stability]\nangle = 0.5\ndistance = 0.02\n"))
    moves, _ = plan_moves(loaded.controls, sizes_of(loaded))
    assert {m.column: m.size for m in moves}["orientation_yaw"] == 0.5
    assert {m.column: m.size for m in moves}["camera_zoom"] == 0.02
    for bad in ("angle = -1", "light = 2", "hdri_rotation = nan", "scene = 3", "steps = 1"):
        with pytest.raises(SpecError) as error:
            load_spec(write_spec(tmp_path, SPEC + f"\n[stability]\n{bad}\n", name="bad.toml"))
        assert "stability" in str(error.value) and "\n" not in str(error.value).strip()


def test_the_neighbours_plan_is_the_runs_scene_one_step_away_and_shares_its_keys(loaded) -> None:
    plan = plan_for(loaded, "m" * 16)
    moves, _ = plan_moves(loaded.controls, sizes_of(loaded))
    jobs = list(plan.jobs)[:5]
    planned = [n for job in jobs for n in neighbour_rows(loaded, job, moves)]
    assert planned and all(n.change.endswith(("°", "%")) for n in planned)
    model = loaded.spec.model
    # an unmoved row (the job itself) plans to the run's own keys: the same stages and cache
    same = variant(loaded, model, [{k: v for k, v in planned[0].row.items()} | _own(loaded, planned[0].base)], moves)
    again = plan_for(same, "m" * 16)
    assert [j.pred_key for j in again.jobs] == [planned[0].base.pred_key]
    assert same.name == "n-stability" and same.spec.policy.type == "table"

    spec = variant(loaded, model, [n.row for n in planned], moves)
    made = plan_for(spec, "m" * 16)
    by_index = {j.index: j for j in list(made.jobs) + list(made.out_of_frame)}
    for n, index in zip(planned, scene_order(loaded, [n.row for n in planned])):
        job = by_index[index]
        assert (job.object, job.environment) == (n.base.object, n.base.environment)
        differs = [(cid, p) for cid, params in job.values.items() for p in params
                   if params[p] != n.base.values[cid][p]]
        assert len(differs) == 1, (n.change, differs)  # exactly the moved parameter
        assert job.pred_key != n.base.pred_key
    keys = {scene_key(n.base.pred_key, n.change, by_index[i].pred_key)
            for n, i in zip(planned, scene_order(loaded, [n.row for n in planned]))}
    assert len(keys) == len(planned)  # one row each
    assert plan_for(variant(loaded, model, [n.row for n in planned], moves), "m" * 16).jobs[0].pred_key == \
        made.jobs[0].pred_key  # planned again: the same keys (a second check renders nothing)


def _own(loaded, job) -> dict:
    """The job's own values as a design row."""
    return {f"{inst.id}_{param}": job.values[inst.id][param] for inst in loaded.controls
            if inst.applies_to(job.object, job.environment) for param, space in inst.spaces.items()
            if isinstance(space, (Choice, Range))}
