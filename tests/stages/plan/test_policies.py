"""Search policies (unit-cube points and choice indices) and the map from points to physical values."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from sweep3d.core.errors import UserError
from sweep3d.spec import Choice, ControlInstance, Fixed, Range
from sweep3d.spec.space import Point, SearchSpace, SpaceShape
from sweep3d.stages.plan.policies import POLICIES, GridPolicy, RandomPolicy
from sweep3d.stages.render.controls import Camera, Orientation
from tests.helpers import TINY_SPEC, examples

FAST = settings(max_examples=examples(120), deadline=None)

shapes = st.builds(
    SpaceShape,
    n_continuous=st.integers(0, 3),
    choice_sizes=st.lists(st.integers(1, 4), max_size=3).map(tuple),
)


def grid(n: int) -> GridPolicy:
    return GridPolicy(GridPolicy.Params(samples_per_dim=n))


def random_policy(samples: int) -> RandomPolicy:
    return RandomPolicy(RandomPolicy.Params(samples=samples))


def check_point(point: Point, shape: SpaceShape) -> None:
    assert len(point.unit) == shape.n_continuous
    assert len(point.choice) == len(shape.choice_sizes)
    assert all(isinstance(u, float) and 0.0 <= u <= 1.0 for u in point.unit)
    assert all(isinstance(c, int) and 0 <= c < size for c, size in zip(point.choice, shape.choice_sizes))


def test_policies_are_registered():
    assert {"grid", "random"} <= set(POLICIES.names())
    assert POLICIES.get("grid") is GridPolicy
    with pytest.raises(UserError, match="valid: adaptive, boundary, grid, random, sobol"):
        POLICIES.get("bayesian")


# -- grid ------------------------------------------------------------------------------------


@FAST
@given(shapes, st.integers(1, 5))
def test_grid_is_the_full_product(shape, n):
    points = grid(n).points(shape, seed=0, history={})
    assert len(points) == n ** shape.n_continuous * math.prod(shape.choice_sizes)
    assert len({(p.unit, p.choice) for p in points}) == len(points)  # no point twice
    for point in points:
        check_point(point, shape)
    for axis, size in enumerate(shape.choice_sizes):
        assert {p.choice[axis] for p in points} == set(range(size))


@FAST
@given(shapes.filter(lambda s: s.n_continuous > 0), st.integers(2, 6))
def test_grid_includes_both_ends_evenly_spaced(shape, n):
    points = grid(n).points(shape, seed=0, history={})
    for axis in range(shape.n_continuous):
        ticks = sorted({p.unit[axis] for p in points})
        assert len(ticks) == n
        assert ticks[0] == 0.0 and ticks[-1] == 1.0
        gaps = [b - a for a, b in zip(ticks, ticks[1:])]
        assert max(gaps) == pytest.approx(min(gaps))


def test_grid_of_one_takes_the_middle():
    points = grid(1).points(SpaceShape(2, (3,)), seed=0, history={})
    assert [p.unit for p in points] == [(0.5, 0.5)] * 3
    assert [p.choice for p in points] == [(0,), (1,), (2,)]


def test_grid_of_an_empty_space_is_one_point():
    assert grid(4).points(SpaceShape(0, ()), seed=0, history={}) == [Point((), ())]


@FAST
@given(shapes, st.integers(0, 2**63 - 1), st.integers(0, 2**63 - 1))
def test_grid_ignores_the_seed(shape, s1, s2):
    assert grid(3).points(shape, s1, history={}) == grid(3).points(shape, s2, history={})


# -- random ----------------------------------------------------------------------------------

seeds = st.integers(0, 2**63 - 1)


@FAST
@given(shapes, seeds, st.integers(1, 40))
def test_random_is_reproducible_and_in_bounds(shape, seed, samples):
    first = random_policy(samples).points(shape, seed, history={})
    again = random_policy(samples).points(shape, seed, history={})
    assert first == again
    assert len(first) == samples
    for point in first:
        check_point(point, shape)


@FAST
@given(shapes.filter(lambda s: s.n_continuous > 0), seeds, seeds)
def test_random_differs_across_seeds(shape, s1, s2):
    assume(s1 != s2)
    a = random_policy(8).points(shape, s1, history={})
    b = random_policy(8).points(shape, s2, history={})
    assert [p.unit for p in a] != [p.unit for p in b]


def test_random_choices_cover_the_options():
    points = random_policy(400).points(SpaceShape(1, (3, 2)), seed=1, history={})
    assert {p.choice for p in points} == {(i, j) for i in range(3) for j in range(2)}
    units = [p.unit[0] for p in points]
    assert min(units) < 0.1 and max(units) > 0.9  # spread over the cube, not a constant


# -- SearchSpace.values ----------------------------------------------------------------------


def instance(control, **spaces) -> ControlInstance:
    return ControlInstance(control, spaces)


bounds = st.tuples(
    st.floats(-1e6, 1e6, allow_nan=False), st.floats(-1e6, 1e6, allow_nan=False)
).filter(lambda b: b[0] < b[1])
log_bounds = st.tuples(st.floats(1e-6, 1e6), st.floats(1e-6, 1e6)).filter(lambda b: b[0] < b[1])
units = st.floats(0.0, 1.0)


@FAST
@given(bounds, log_bounds, units, units, st.integers(0, 2))
def test_values_stay_inside_declared_ranges(lin, log, u1, u2, index):
    orientation = instance(Orientation("o", "orientation"), yaw=Range(*lin), roll=Fixed(5.0))
    camera = instance(Camera("cam", "camera"), zoom=Range(*log, log=True), elevation=Choice((0.0, 30.0, 60.0)))
    space = SearchSpace([orientation, camera])
    assert (space.shape.n_continuous, space.shape.choice_sizes) == (2, (3,))

    values = space.values(Point((u1, u2), (index,)))

    assert lin[0] <= values["o"]["yaw"] <= lin[1]
    assert log[0] <= values["cam"]["zoom"] <= log[1]
    assert values["o"]["roll"] == 5.0
    assert values["cam"]["elevation"] == (0.0, 30.0, 60.0)[index]
    assert set(values["o"]) == {"yaw", "roll"} and set(values["cam"]) == {"zoom", "elevation"}


@FAST
@given(bounds, units, units)
def test_linear_range_is_monotone_and_hits_the_ends(lin, u, v):
    r = Range(*lin)
    assert r.at(0.0) == lin[0] and r.at(1.0) == lin[1]
    if u < v:
        assert r.at(u) <= r.at(v)
    assert r.at(0.5) == pytest.approx((lin[0] + lin[1]) / 2, rel=1e-9, abs=1e-6)


@FAST
@given(log_bounds, units)
def test_log_range_is_geometric(log, u):
    r = Range(*log, log=True)
    assert r.at(0.0) == log[0] and r.at(1.0) == log[1]  # declared bounds exactly, not exp(log(x))
    assert r.at(0.5) == pytest.approx(math.sqrt(log[0] * log[1]), rel=1e-9)
    assert log[0] <= r.at(u) <= log[1]


@FAST
@given(st.integers(-1000, 1000), st.integers(1, 1000), units)
def test_integer_range_gives_ints_inside(low, width, u):
    r = Range(float(low), float(low + width), integer=True)
    value = r.at(u)
    assert isinstance(value, int)
    assert low <= value <= low + width


def test_out_of_cube_units_are_clamped():
    r = Range(10.0, 20.0)
    assert r.at(-0.5) == 10.0 and r.at(1.5) == 20.0


def test_point_must_match_the_shape():
    space = SearchSpace([instance(Orientation("o", "orientation"), yaw=Range(0.0, 1.0))])
    with pytest.raises(ValueError, match="shape"):
        space.values(Point((0.5, 0.5), ()))
    with pytest.raises(ValueError, match="shape"):
        space.values(Point((0.5,), (0,)))


def test_grid_over_a_space_reaches_every_declared_value():
    orientation = instance(Orientation("o", "orientation"), yaw=Range(-90.0, 90.0), pitch=Choice((0.0, 45.0)))
    space = SearchSpace([orientation])
    values = [space.values(p)["o"] for p in grid(3).points(space.shape, seed=0, history={})]
    assert sorted({v["yaw"] for v in values}) == [-90.0, 0.0, 90.0]
    assert {v["pitch"] for v in values} == {0.0, 45.0}
    assert len(values) == 6


def test_grid_over_a_full_turn_does_not_repeat_its_end(tmp_path) -> None:
    """yaw over [-180, 180]: six distinct poses, not five plus -180 and 180 twice."""
    from tests.helpers import load_spec, plan_for, write_spec

    body = TINY_FULL_TURN
    plan = plan_for(load_spec(write_spec(tmp_path, body)), "m")
    yaws = sorted(j.values["orientation"]["yaw"] for j in plan.jobs if j.environment == "white")
    assert yaws == [-180.0, -120.0, -60.0, 0.0, 60.0, 120.0]
    assert len({j.render_key for j in plan.jobs}) == len(plan.jobs)
    half = plan_for(load_spec(write_spec(tmp_path, body.replace("[-180, 180]", "[0, 180]"))), "m")
    assert max(j.values["orientation"]["yaw"] for j in half.jobs) == 180.0  # a partial range keeps both ends


TINY_FULL_TURN = (
    TINY_SPEC.replace("yaw = [0, 45]", "yaw = { range = [-180, 180] }")
    .replace("sigma = [0.0, 1.5]", "sigma = 0.0")
    .replace('[policy]\ntype = "grid"', '[policy]\ntype = "grid"\nsamples_per_dim = 6')
)


def test_sobol_is_reproducible_in_range_and_more_even_than_random() -> None:
    from scipy.stats import qmc

    from sweep3d.stages.plan.policies import POLICIES

    sobol = POLICIES.get("sobol")(POLICIES.get("sobol").Params(samples=256))
    rand = POLICIES.get("random")(POLICIES.get("random").Params(samples=256))
    shape = SpaceShape(2, (3,))
    points = sobol.points(shape, seed=5, history={})
    assert points == sobol.points(shape, seed=5, history={}) and points != sobol.points(shape, seed=6, history={})
    assert all(0 <= u <= 1 for p in points for u in p.unit) and {p.choice[0] for p in points} == {0, 1, 2}
    unit = np.array([p.unit for p in points])
    random_unit = np.array([p.unit for p in rand.points(shape, seed=5, history={})])
    assert qmc.discrepancy(unit) < qmc.discrepancy(random_unit)


def _adaptive(**kw):
    from sweep3d.stages.plan.policies import POLICIES

    cls = POLICIES.get("adaptive")
    return cls(cls.Params(**kw))


def _evaluate(points, fails):
    from sweep3d.stages.plan.policies import Outcome

    return {p: Outcome(failed=fails(p), loss=float(fails(p))) for p in points}


def test_adaptive_rounds_extend_a_fixed_prefix_and_stop_at_the_budget() -> None:
    policy = _adaptive(samples=40, initial=8, batch=8)
    shape = SpaceShape(2, (3,))
    fails = lambda p: p.unit[0] > 0.8  # noqa: E731  (a failure region: the top fifth of dim 0)
    history: dict = {}
    seen: list = []
    for _ in range(10):
        points = policy.points(shape, seed=3, history=history)
        assert points[: len(seen)] == seen, "earlier rounds never change"
        if len(points) == len(seen):
            break
        seen = points
        history = _evaluate(points, fails)
    assert len(seen) == 40 and len(set(seen)) == 40
    assert all(0 <= u <= 1 for p in seen for u in p.unit) and all(0 <= p.choice[0] < 3 for p in seen)
    assert policy.points(shape, seed=3, history=history) == seen  # pure function of its inputs


def test_adaptive_concentrates_samples_where_the_model_fails() -> None:
    shape = SpaceShape(2, ())
    fails = lambda p: p.unit[0] > 0.8 and p.unit[1] < 0.3  # noqa: E731  (6 % of the square)
    history: dict = {}
    policy = _adaptive(samples=96, initial=16, batch=16)
    for _ in range(10):
        points = policy.points(shape, seed=11, history=history)
        history = _evaluate(points, fails)
    later = points[16:]
    assert sum(map(fails, later)) / len(later) > 0.3  # versus 0.06 for uniform sampling


def test_adaptive_wraps_periodic_dims_instead_of_clipping() -> None:
    shape = SpaceShape(1, (), wraps=(True,))
    fails = lambda p: p.unit[0] > 0.97 or p.unit[0] < 0.03  # noqa: E731
    history: dict = {}
    policy = _adaptive(samples=64, initial=16, batch=16, radius=0.2)
    for _ in range(6):
        points = policy.points(shape, seed=2, history=history)
        history = _evaluate(points, fails)
    assert not any(p.unit[0] in (0.0, 1.0) for p in points[16:])  # clipping would pile points on the ends


# -- counting jobs before making them --------------------------------------------------------


@FAST
@given(shapes, st.integers(1, 4), st.integers(1, 12), seeds)
def test_grid_and_random_count_their_points_without_making_them(shape, n, samples, seed):
    for policy in (grid(n), random_policy(samples)):
        assert policy.count(shape) == len(policy.points(shape, seed, history={}))


@pytest.mark.parametrize("shape", [SpaceShape(0, ()), SpaceShape(2, (3,)), SpaceShape(1, (), wraps=(True,))])
def test_sobol_and_adaptive_count_their_points_without_making_them(shape):
    sobol = POLICIES.get("sobol")
    assert sobol(sobol.Params(samples=12)).count(shape) == len(sobol(sobol.Params(samples=12)).points(shape, 5, {}))
    adaptive = _adaptive(samples=12, initial=4, batch=4)
    history: dict = {}
    points: list = []
    while not points or len(history) < len(points):  # round after round, failing everywhere, until it stops
        points = adaptive.points(shape, 5, history)
        history = _evaluate(points, lambda p: True)
    assert len(points) <= adaptive.count(shape)
    assert adaptive.count(shape) == (12 if shape.n_continuous or shape.choice_sizes else 1)


def test_a_users_policy_that_cannot_count_says_so():
    from sweep3d.stages.plan.policies import Policy, PolicyParams

    assert Policy(PolicyParams()).count(SpaceShape(2, (3,))) is None


FILTERED = TINY_SPEC.replace("yaw = [0, 45]", 'yaw = { range = [0, 90] }\nenvironments = ["studio"]').replace(
    '[policy]\ntype = "grid"', '[[controls]]\ntype = "camera"\nelevation = [0, 10, 20]\nobjects = ["box"]\n\n'
                               '[policy]\ntype = "grid"\nsamples_per_dim = 3')


def test_the_job_count_matches_the_plan_with_controls_limited_to_some_scenes(tmp_path) -> None:
    from sweep3d.stages.plan import count_jobs
    from tests.helpers import load_spec, plan_for, write_spec

    loaded = load_spec(write_spec(tmp_path, FILTERED))
    plan = plan_for(loaded, "m")
    assert count_jobs(loaded) == len(plan.jobs) + len(plan.out_of_frame) == 2 * 3 + 2 * 3 * 3  # white: no yaw


HUGE_GRID = TINY_SPEC.replace("yaw = [0, 45]", "yaw = { range = [0, 90] }\npitch = { range = [0, 90] }").replace(
    "sigma = [0.0, 1.5]", "sigma = { range = [0, 2] }").replace(
    '[policy]\ntype = "grid"', '[policy]\ntype = "grid"\nsamples_per_dim = 1000')  # 2 scenes × 1000³ = 2·10⁹


def test_a_billion_job_grid_is_refused_in_one_line_before_anything_is_made(tmp_path) -> None:
    import resource
    import time

    from sweep3d.core.errors import SpecError
    from tests.helpers import load_spec, plan_for, write_spec

    loaded = load_spec(write_spec(tmp_path, HUGE_GRID))
    memory = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    started = time.perf_counter()
    with pytest.raises(SpecError) as caught:
        plan_for(loaded, "m")
    assert time.perf_counter() - started < 0.5
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - memory < 50_000  # KiB: nothing big was allocated
    assert caught.value.key == "policy"
    message = str(caught.value)
    assert "\n" not in message
    for text in ("2,000,000,000 jobs", "limit of 1,000,000", "policy.samples_per_dim", "[experiment] max_jobs"):
        assert text in message, message


def test_max_jobs_raises_or_lowers_the_limit(tmp_path) -> None:
    from sweep3d.core.errors import SpecError
    from tests.helpers import load_spec, plan_for, write_spec

    body = FILTERED.replace('seed = 7', 'seed = 7\nmax_jobs = 23')
    with pytest.raises(SpecError, match=r"expands to 24 jobs, over the limit of 23"):
        plan_for(load_spec(write_spec(tmp_path, body)), "m")
    assert len(plan_for(load_spec(write_spec(tmp_path, body.replace("max_jobs = 23", "max_jobs = 24"))), "m").jobs)
    random = body.replace('type = "grid"\nsamples_per_dim = 3', 'type = "random"\nsamples = 12')
    with pytest.raises(SpecError, match=r"24 jobs, over the limit of 23; lower policy.samples"):
        plan_for(load_spec(write_spec(tmp_path, random)), "m")


class Uncounted(GridPolicy):
    """A user's policy that does not override ``count``."""

    def count(self, shape):
        return None


def test_a_policy_that_cannot_count_is_stopped_as_its_points_come(tmp_path) -> None:
    import dataclasses

    from sweep3d.core.errors import SpecError
    from tests.helpers import load_spec, plan_for, write_spec

    loaded = load_spec(write_spec(tmp_path, FILTERED.replace('seed = 7', 'seed = 7\nmax_jobs = 20')))
    loaded = dataclasses.replace(loaded, policy=Uncounted(loaded.policy.params))
    with pytest.raises(SpecError, match=r"expands to more than 20 jobs, over the limit of 20"):
        plan_for(loaded, "m")
