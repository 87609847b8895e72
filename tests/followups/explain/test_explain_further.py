"""Fixes you can trust, on a synthetic model (no render): the nearest fix is found by the pure
search, its margin read from the model, the stability check's rule marks it fragile, and the
further search goes past a fragile fix along its own change until the margin clears the
threshold (or marks it fragile when nothing further does, or the budget ends first)."""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sweep3d.followups.explain.further import Judged, is_fragile, needs_further, search_further, steps_beyond
from sweep3d.followups.explain.search import Axis, Config, Fix, Move, explain
from sweep3d.spec.space import Point
from tests.helpers import examples

SCENE = ("box", "white")
RESOLUTION = 1 / 64
X = [Axis("x", "range", 0)]


def ramp(boundary: float, slope: float, cap: float = 1.0):
    """A model wrong below ``boundary`` on x, right above it, surer the farther: margin
    ``slope * (x - boundary)``, clipped to ±``cap``."""
    def margin(config: Config) -> float:
        return max(-cap, min(cap, slope * (config.point.unit[0] - boundary)))
    return margin


def judge_with(margin, threshold: float | None, asked: list[Config] | None = None):
    def judge(configs: list[Config]) -> list[Judged]:
        if asked is not None:
            asked.extend(configs)
        out = []
        for c in configs:
            m = margin(c)
            out.append(Judged(m > 0, m, is_fragile(m, threshold) if m > 0 else None))
        return out
    return judge


def nearest_marked(start: float, margin, threshold: float | None) -> Fix:
    """The pure search's nearest fix from x = ``start``, its margin and fragility filled in (as
    the driver fills them from the stored verdicts)."""
    (fix,) = explain([Config(SCENE, Point((start,), ()))], lambda scene: X,
                     lambda configs: [margin(c) > 0 for c in configs], resolution=RESOLUTION)
    assert fix.fix is not None
    m = margin(fix.fix)
    return dataclasses.replace(fix, margin=m, fragile=is_fragile(m, threshold))


def test_the_rule_is_the_stability_checks() -> None:
    assert is_fragile(0.01, 0.05) is True and is_fragile(-0.01, 0.05) is True  # |margin| below the threshold
    assert is_fragile(0.05, 0.05) is False and is_fragile(0.3, 0.05) is False
    assert is_fragile(0.3, 0.05, flipped=True) is True  # its image flipped in the check
    assert is_fragile(0.01, None) is None and is_fragile(0.01, None, flipped=True) is None  # no check: unknown
    assert is_fragile(None, 0.05) is None
    assert is_fragile(0.01, 0.0) is False  # a check where no bin flips beyond doubt: only flipped images


def test_a_nearest_fix_that_is_a_near_tie_is_fragile_and_a_sturdier_one_lies_further_along() -> None:
    margin, threshold = ramp(0.5, 1.0), 0.05
    fix = nearest_marked(0.3, margin, threshold)
    assert 0 < fix.margin < threshold and fix.fragile and needs_further(fix)  # within 1/64 of the edge: a near tie
    asked: list[Config] = []
    (sturdy,) = search_further([fix], lambda scene: X, judge_with(margin, threshold, asked),
                               resolution=RESOLUTION).fixes
    assert sturdy.fragile is False and sturdy.margin >= threshold and sturdy.margin == margin(sturdy.fix)
    assert sturdy.nearest == fix and sturdy.distance > fix.distance
    assert [m.axis for m in sturdy.moves] == ["x"] and sturdy.moves[0].share > 0  # the same change, further
    # the first of the steps 1, 2, 4, … search steps past the nearest fix that clears the threshold
    t = fix.moves[0].share
    steps = [t + k * RESOLUTION for k in (1, 2, 4, 8, 16, 32)]
    first = next(u for u in steps if margin(Config(SCENE, Point((0.3 + u,), ()))) >= threshold)
    assert sturdy.moves[0].share == pytest.approx(first)
    assert sturdy.further == len(asked) == steps.index(first) + 1
    assert sturdy.probes == fix.probes + sturdy.further


def test_a_fix_nothing_further_makes_sturdier_stays_and_is_marked_fragile() -> None:
    margin, threshold = ramp(0.5, 1.0, cap=0.03), 0.05  # the model never gets surer than 0.03
    fix = nearest_marked(0.3, margin, threshold)
    (same,) = search_further([fix], lambda scene: X, judge_with(margin, threshold), resolution=RESOLUTION).fixes
    assert same.fix == fix.fix and same.fragile is True and same.nearest is None and same.complete
    assert same.further == len(steps_beyond(fix, X, RESOLUTION)) > 0  # every step to the range's end was asked
    assert steps_beyond(fix, X, RESOLUTION)[-1][0].point.unit[0] == 1.0


def test_a_sturdy_fix_and_an_unknown_one_are_not_searched_further() -> None:
    margin = ramp(0.5, 20.0)  # steep: the nearest fix is already sure
    sure = nearest_marked(0.3, margin, 0.05)
    unknown = nearest_marked(0.3, ramp(0.5, 1.0), None)  # no stability check yet
    assert sure.fragile is False and unknown.fragile is None
    asked: list[Config] = []
    out = search_further([sure, unknown], lambda scene: X, judge_with(margin, 0.05, asked)).fixes
    assert out == [sure, unknown] and not asked


def test_the_budget_holds_and_a_fix_it_stops_is_marked_fragile_and_incomplete() -> None:
    margin, threshold = ramp(0.5, 1.0), 0.05
    fixes = [nearest_marked(start, margin, threshold) for start in (0.1, 0.3, 0.45)]
    for budget in (0, 1, 3):
        asked: list[Config] = []
        done = search_further(fixes, lambda scene: X, judge_with(margin, threshold, asked), budget=budget,
                              resolution=RESOLUTION)
        assert done.charged <= budget and len(set(asked)) <= budget
        for before, after in zip(fixes, done.fixes):
            if after.nearest is None:  # not replaced: the budget stopped it
                assert after.fix == before.fix and after.fragile is True and after.complete is False
    asked = []
    free = search_further(fixes, lambda scene: X, judge_with(margin, threshold, asked), budget=0,
                          free=lambda c: True, resolution=RESOLUTION)
    assert all(f.fragile is False for f in free.fixes) and free.charged == 0  # nothing charged: it never bites


def test_a_change_of_list_options_only_has_nothing_further_along_it() -> None:
    axes = [Axis("s", "list", 0, size=3)]
    failure = Config(SCENE, Point((), (0,)))
    fix = Fix(failure, Config(SCENE, Point((), (1,))), (Move("s", 0.5),), 0.5, 2, True, 0.01, True)
    assert steps_beyond(fix, axes, RESOLUTION) == []
    (same,) = search_further([fix], lambda scene: axes, judge_with(lambda c: 0.01, 0.05)).fixes
    assert same == dataclasses.replace(fix, further=0)


def test_a_pair_and_a_wrapping_range_go_on_along_the_same_diagonal() -> None:
    axes = [Axis("yaw", "range", 0, wraps=True), Axis("s", "list", 0, size=3), Axis("y", "range", 1)]
    failure = Config(SCENE, Point((0.95, 0.2), (0,)))
    fix = Fix(failure, Config(SCENE, Point((0.98, 0.23), (0,))), (Move("y", 0.03), Move("yaw", 0.03)),
              math.hypot(0.03, 0.03), 4, True, 0.01, True)
    steps = steps_beyond(fix, axes, RESOLUTION)
    assert len(steps) > 2
    for config, moves, distance in steps:
        (y, t), (yaw, t2) = [(m.axis, m.share) for m in moves]
        assert (y, yaw) == ("y", "yaw") and t == t2 > 0.03
        assert config.point.unit[0] == pytest.approx((0.95 + t) % 1.0)  # across the wrap
        assert config.point.unit[1] == pytest.approx(0.2 + t) and distance == pytest.approx(math.sqrt(2) * t)
    assert steps[-1][1][0].share == pytest.approx(0.5)  # half a turn: the wrapping range's end


@settings(max_examples=examples(60), deadline=None)
@given(boundary=st.floats(0.2, 0.95), start=st.floats(0.0, 0.19), slope=st.floats(0.05, 50.0),
       threshold=st.floats(0.0, 0.3), cap=st.floats(0.01, 1.0))
def test_a_searched_fix_is_right_and_either_clears_the_threshold_or_is_marked_fragile(
        boundary, start, slope, threshold, cap) -> None:
    margin = ramp(boundary, slope, cap)
    fix = nearest_marked(start, margin, threshold)
    (out,) = search_further([fix], lambda scene: X, judge_with(margin, threshold), resolution=RESOLUTION).fixes
    assert margin(out.fix) > 0 and out.margin == margin(out.fix)
    assert out.distance >= fix.distance
    if out.fragile:  # no step further along cleared the threshold
        assert out.fix == fix.fix and out.nearest is None
        assert all(margin(c) < threshold for c, _, _ in steps_beyond(fix, X, RESOLUTION))
    else:
        assert out.margin >= threshold
        assert out.nearest == (fix if fix.fragile else None)
