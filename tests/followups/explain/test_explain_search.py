"""The pure nearest-fix search against a synthetic model that fails exactly inside a known box:
every fix lands within one search step of the box's edge, the budget holds, the seed decides."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sweep3d.followups.explain.search import Axis, Config, explain
from sweep3d.spec.space import Point

SCENE = ("box", "white")
AXES = [Axis("x", "range", 0), Axis("y", "range", 1), Axis("yaw", "range", 2, wraps=True), Axis("z", "list", 0, size=4)]
LOW, HIGH = (0.3, 0.2, 0.9), (0.6, 0.7, 1.15)  # yaw's interval crosses its wrap: 0.9 .. 1.0 and 0 .. 0.15
BAD_OPTIONS = {1, 2}
RESOLUTION = 1 / 64


def inside(point: Point) -> bool:
    x, y, yaw = point.unit
    yaw_in = yaw >= LOW[2] or yaw <= HIGH[2] - 1.0
    return LOW[0] <= x <= HIGH[0] and LOW[1] <= y <= HIGH[1] and yaw_in and point.choice[0] in BAD_OPTIONS


def oracle(calls: list[int]):
    def answer(configs: list[Config]) -> list[bool]:
        calls.append(len(configs))
        return [not inside(c.point) for c in configs]
    return answer


def failures(n: int, seed: int = 3) -> list[Config]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        x, y = rng.uniform(LOW[0], HIGH[0]), rng.uniform(LOW[1], HIGH[1])
        yaw = (rng.uniform(LOW[2], HIGH[2])) % 1.0
        out.append(Config(SCENE, Point((float(x), float(y), float(yaw)), (int(rng.choice(sorted(BAD_OPTIONS))),))))
    assert all(inside(c.point) for c in out)
    return out


def edge_gaps(start: Point, fix: Point) -> list[float]:
    """For each range moved, how far the fix lies beyond the box face it crossed (share of range)."""
    gaps = []
    for d in range(3):
        a, b = start.unit[d], fix.unit[d]
        if a == b:
            continue
        if d == 2:  # the wrapping axis: the distance past the nearer end of the arc 0.9 .. 1.15
            past_high, past_low = (b - (HIGH[2] - 1.0)) % 1.0, (LOW[2] - b) % 1.0
            gaps.append(min(past_high, past_low))
        else:
            gaps.append(b - HIGH[d] if b > HIGH[d] else LOW[d] - b if b < LOW[d] else math.inf)
    return gaps


def nearest_exit(point: Point) -> float:
    """The true nearest single-parameter fix (the box is axis-aligned: no pair is nearer)."""
    x, y, yaw = point.unit
    yaw_exits = ((HIGH[2] - 1.0 - yaw) % 1.0, (yaw - LOW[2]) % 1.0)
    z = point.choice[0]
    return min(x - LOW[0], HIGH[0] - x, y - LOW[1], HIGH[1] - y, *yaw_exits, 1 / 3 if z in (1, 2) else 0)


def test_every_fix_lands_within_one_step_of_the_failing_regions_edge() -> None:
    calls: list[int] = []
    fixes = explain(failures(24), lambda scene: AXES, oracle(calls), resolution=RESOLUTION, seed=1)
    assert len(fixes) == 24 and all(f.complete for f in fixes)
    for fix in fixes:
        assert fix.fix is not None and not inside(fix.fix.point)
        assert fix.fix.scene == SCENE
        gaps = edge_gaps(fix.failure.point, fix.fix.point)
        assert all(0 <= g <= RESOLUTION + 1e-12 for g in gaps), (fix, gaps)
        assert fix.distance <= nearest_exit(fix.failure.point) + RESOLUTION + 1e-12, fix
        moved = {m.axis for m in fix.moves}
        assert len(moved) == 1  # an axis-aligned box is left nearest along one parameter
        assert math.isclose(fix.distance, math.sqrt(sum(m.share ** 2 for m in fix.moves)))
        if moved == {"z"}:
            assert fix.fix.point.choice[0] not in BAD_OPTIONS and abs(fix.moves[0].share) == pytest.approx(1 / 3)
    assert max(calls) > 1  # the failures' probes are asked together, in batches


def test_a_budget_is_never_exceeded_and_free_configurations_cost_nothing() -> None:
    asked: list[Config] = []

    def counting(configs: list[Config]) -> list[bool]:
        asked.extend(configs)
        return [not inside(c.point) for c in configs]

    everything = explain(failures(12), lambda scene: AXES, counting, seed=2)
    total = len(asked)
    for budget in (0, 5, 30, total // 2):
        asked.clear()
        fixes = explain(failures(12), lambda scene: AXES, counting, seed=2, budget=budget, concurrent=4)
        assert len(set(asked)) <= budget
        assert len(fixes) < len(everything) or not all(f.complete for f in fixes)
        assert all(not inside(f.fix.point) for f in fixes if f.fix is not None)
        order = [f.failure for f in everything]  # the seeded order: the failures reached are its first ones
        assert [f.failure for f in fixes] == order[:len(fixes)], "a random sample, not those with cheap probes"
    fixes = explain(failures(12), lambda scene: AXES, counting, seed=2, budget=0, free=lambda c: True)
    assert len(fixes) == 12 and all(f.complete for f in fixes)  # nothing charged: the budget never bites
    assert [f.fix for f in fixes] == [f.fix for f in everything]


def test_the_same_seed_gives_the_same_counterfactuals_and_another_seed_another_order() -> None:
    def run(seed: int):
        return explain(failures(20), lambda scene: AXES, oracle([]), seed=seed, budget=120, concurrent=3)

    first, again, other = run(5), run(5), run(6)
    assert first == again
    assert [f.failure for f in first] != [f.failure for f in other]


def test_a_pair_is_found_where_no_single_parameter_fixes_and_lists_move_to_neighbours() -> None:
    """Right only where x and y are both high: no single move fixes a failure at the origin."""
    axes = [Axis("x", "range", 0), Axis("y", "range", 1), Axis("s", "list", 0, size=3)]

    def answer(configs: list[Config]) -> list[bool]:
        return [c.point.unit[0] > 0.5 and c.point.unit[1] > 0.5 and c.point.choice[0] == 0 for c in configs]

    start = Config(SCENE, Point((0.2, 0.2), (1,)))
    (fix,) = explain([start], lambda scene: axes, answer, resolution=RESOLUTION)
    assert fix.fix is None and fix.complete  # the list must move too: three parameters, beyond pairs
    start = Config(SCENE, Point((0.2, 0.2), (0,)))
    (fix,) = explain([start], lambda scene: axes, answer, resolution=RESOLUTION)
    assert {m.axis for m in fix.moves} == {"x", "y"}
    assert all(0.3 < m.share <= 0.3 + RESOLUTION for m in fix.moves), fix.moves
    assert fix.distance == pytest.approx(math.sqrt(2) * fix.moves[0].share)


def test_the_oracle_is_asked_each_configuration_once() -> None:
    asked: list[Config] = []

    def counting(configs: list[Config]) -> list[bool]:
        asked.extend(configs)
        return [not inside(c.point) for c in configs]

    same = failures(1) * 3  # three failures at one configuration share every probe
    fixes = explain(same, lambda scene: AXES, counting)
    assert len(asked) == len(set(asked))
    assert fixes[0].fix == fixes[1].fix == fixes[2].fix


def test_a_change_across_a_whole_turn_is_written_the_short_way_round(tmp_path) -> None:
    """Yaw over −180..180 wraps: from 172.8° to −172.8° is +14.4°, 4 % of the range, not −345.6°."""
    from sweep3d.followups.explain.run import _changes, _written, scene_axes
    from sweep3d.followups.explain.search import Fix, Move
    from tests.helpers import TINY_SPEC, load_spec, write_spec

    body = TINY_SPEC.replace("yaw = [0, 45]", "yaw = { range = [-180, 180] }")
    spec = load_spec(write_spec(tmp_path, body))
    space, axes = scene_axes(spec, ("box", "white"))
    assert [(a.name, a.kind, a.wraps) for a in axes] == [("orientation_yaw", "range", True), ("blur_sigma", "list", False)]
    failure = Config(("box", "white"), Point((0.98,), (1,)))
    fix = Fix(failure, Config(failure.scene, Point((0.02,), (0,))), (Move("blur_sigma", -1.0), Move("orientation_yaw", 0.04)),
              math.hypot(1.0, 0.04), 3, True)
    changes = {c[0]: c for c in _changes(space, fix)}
    assert changes["orientation_yaw"][3] == pytest.approx(14.4)
    assert changes["blur_sigma"][1:4] == ("1.5", "0", -1.5)
    assert _written(changes["orientation_yaw"]) == "orientation_yaw +14.4 (4.0% of its range)"


def test_the_failures_a_budget_reaches_are_the_first_of_the_seeded_order() -> None:
    """When the budget runs out, a failure whose probes happen to be free (another scene's, already
    evaluated) is not taken in place of those before it: the reached stay a random sample."""
    cheap = ("ball", "white")
    mixed = failures(8) + [Config(cheap, c.point) for c in failures(8, seed=4)]
    free = lambda c: c.scene == cheap  # noqa: E731
    everything = explain(mixed, lambda scene: AXES, oracle([]), seed=1, free=free)
    order = [f.failure for f in everything]
    fixes = explain(mixed, lambda scene: AXES, oracle([]), seed=1, budget=10, free=free, concurrent=2)
    assert 0 < len(fixes) < len(mixed)
    assert [f.failure for f in fixes] == order[:len(fixes)]
