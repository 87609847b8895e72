"""The statistics of ``sweep3d confirm`` with a synthetic oracle: nothing is rendered.

A true region (the oracle fails exactly there, or mostly there) must be confirmed in at least
95 % of seeds; a chance region, picked because it looked significant in a small discovery set
where nothing matters, must be called confirmed in no more seeds than the stated error rate."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.stats import hypergeom

from sweep3d.followups.confirm.claims import boundary_claim, value_claim
from sweep3d.followups.confirm.draw import Parameter, Space, draw_pairs
from sweep3d.results.confirmation import (
    ALPHA,
    CONFIRMED,
    DEFAULT_RENDERS,
    INCONCLUSIVE,
    NOT_REPLICATED,
    UNCONFIRMED,
    Pairs,
    family_of,
    holm,
    judge,
    mcnemar_one_sided,
    paired_difference_interval,
    pairs_needed,
    pairs_to_confirm,
    tally,
    wilson,
)
from sweep3d.results.views import wilson_interval
from sweep3d.spec.params import Choice, Range

SCENES = frozenset({("mug", "white"), ("mug", "studio"), ("toaster", "white"), ("toaster", "studio")})
SPACE = Space(
    objects=("mug", "toaster"), environments=("white", "studio"),
    parameters=(
        Parameter("orientation_yaw", "orientation", "yaw", Range(-180.0, 180.0), SCENES),
        Parameter("camera_elevation", "camera", "elevation", Range(0.0, 80.0), SCENES),
        Parameter("occluder_coverage", "occluder", "coverage", Choice(("none", "half", "full")),
                  frozenset({("mug", "white"), ("mug", "studio")})),
    ))
SEEDS = 200


def boundary_row(parameter: str, fails: str, at: float, scope: str = "all", name: str | None = None) -> dict:
    return {"parameter": parameter, "scope": scope, "object": name if scope == "object" else None,
            "environment": name if scope == "environment" else None, "fails": fails, "boundary": at,
            "values": 40, "boundary_low": at - 1, "boundary_high": at + 1}


def verdict_of(claim, oracle, seed: int, pairs: int = DEFAULT_RENDERS // 2):
    """The verdict on ``pairs`` fresh twin pairs judged by ``oracle(row, rng) -> correct``."""
    rng = np.random.default_rng([seed, 99])
    drawn = draw_pairs(SPACE, claim, pairs, seed)
    return judge([tally((oracle(a, rng), oracle(b, rng)) for a, b in drawn)])[0]


# -- the pure pieces -------------------------------------------------------------------------------

def test_the_one_sided_mcnemar_p_is_the_binomial_tail_of_the_discordant_pairs() -> None:
    assert mcnemar_one_sided(0, 0) == 1.0
    assert mcnemar_one_sided(5, 0) == pytest.approx(1 / 32)
    assert mcnemar_one_sided(0, 5) == 1.0  # against the finding: no evidence for it
    assert mcnemar_one_sided(3, 1) == pytest.approx(5 / 16)  # P(X >= 3), X ~ Bin(4, 1/2)


def test_wilson_is_the_views_interval() -> None:
    for k, n in ((0, 5), (3, 7), (12, 12), (40, 97)):
        assert wilson(k, n) == pytest.approx(wilson_interval(k, n), abs=1e-12)


def test_holm_steps_down_and_stays_monotone() -> None:
    assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
    assert holm([]) == []


def test_tally_counts_each_cell() -> None:
    pairs = tally([(True, True), (False, True), (False, True), (True, False), (False, False)])
    assert (pairs.both_right, pairs.inside_wrong, pairs.inside_right, pairs.both_wrong) == (1, 2, 1, 1)
    assert pairs.accuracy_inside == pytest.approx(2 / 5) and pairs.accuracy_outside == pytest.approx(3 / 5)


def test_the_paired_interval_holds_the_difference_and_covers_it_95_percent_of_the_time() -> None:
    rng = np.random.default_rng(3)
    p_inside, p_outside, flip, n = 0.4, 0.7, 0.3, 40
    truth = p_inside - (p_outside * (1 - flip) + (1 - p_outside) * flip)
    covered = 0
    for _ in range(2000):
        shared = rng.random(n)  # correlated twins: a hard configuration is hard on both sides
        inside = shared < p_inside
        outside = (shared < p_outside) ^ (rng.random(n) < flip)
        pairs = tally(zip(inside, outside))
        low, high = paired_difference_interval(pairs)
        difference = pairs.accuracy_inside - pairs.accuracy_outside
        assert -1 <= low <= difference <= high <= 1
        covered += low <= truth <= high
    assert covered / 2000 >= 0.93  # Newcombe reports 93-95 % at small n


def test_a_finding_without_pairs_is_unconfirmed_and_left_out_of_the_family() -> None:
    empty, strong = judge([Pairs(), Pairs(inside_wrong=8)])
    assert empty.status == UNCONFIRMED and empty.difference is None
    assert strong.status == CONFIRMED and strong.findings == 1 and strong.p_holm == pytest.approx(2 ** -8)


# -- drawing ---------------------------------------------------------------------------------------

def test_twins_differ_only_in_the_claims_parameter_and_fall_on_its_two_sides() -> None:
    claim = boundary_claim(boundary_row("camera_elevation", "above", 40.0), "elevation fails above 40",
                           Range(0.0, 80.0))
    for inside, outside in draw_pairs(SPACE, claim, 50, seed=1):
        assert inside["camera_elevation"] > 40 >= outside["camera_elevation"]
        rest = lambda row: {k: v for k, v in row.items() if k != "camera_elevation"}  # noqa: E731
        assert rest(inside) == rest(outside)
        assert ("occluder_coverage" in inside) == (inside["object"] == "mug")  # only where it applies


def test_draws_are_seeded_per_claim() -> None:
    claim = value_claim("occluder_coverage", "half", "", Choice(("none", "half", "full")))
    assert draw_pairs(SPACE, claim, 10, seed=4) == draw_pairs(SPACE, claim, 10, seed=4)
    assert draw_pairs(SPACE, claim, 10, seed=4) != draw_pairs(SPACE, claim, 10, seed=5)
    for inside, outside in draw_pairs(SPACE, claim, 30, seed=4):
        assert inside["object"] == "mug"  # the occluder applies to the mug only
        assert inside["occluder_coverage"] == "half" != outside["occluder_coverage"]


def test_a_bin_claim_draws_inside_the_bin_and_outside_it_over_the_rest_of_the_range() -> None:
    claim = value_claim("orientation_yaw", "80–110", "", Range(-180.0, 180.0), level_value=95.0, width=30.0)
    drawn = draw_pairs(SPACE, claim, 200, seed=2)
    assert all(80 <= a["orientation_yaw"] <= 110 for a, _ in drawn)
    assert all(not 80 <= b["orientation_yaw"] <= 110 for _, b in drawn)
    assert min(b["orientation_yaw"] for _, b in drawn) < -100 and max(b["orientation_yaw"] for _, b in drawn) > 120


def test_an_object_claim_swaps_the_object_and_keeps_the_rest() -> None:
    claim = value_claim("object", "toaster", "", None, ("mug", "toaster"))
    for inside, outside in draw_pairs(SPACE, claim, 20, seed=3):
        assert (inside["object"], outside["object"]) == ("toaster", "mug")
        assert inside["environment"] == outside["environment"]
        assert inside["orientation_yaw"] == outside["orientation_yaw"]


def _rendered(row: dict) -> tuple:
    """What a twin's render depends on here (the occluder's coverage stands for a post control: left out)."""
    return row["object"], row["environment"], row["orientation_yaw"], row["camera_elevation"]


def test_claims_in_the_same_scenes_share_their_twins_renders() -> None:
    """Two claims on a post-like parameter (the occluder) in the same scenes start each pair from
    the scene's same base: their twins are the same renders; an elevation claim's differ from them
    in one twin at most."""
    half = value_claim("occluder_coverage", "half", "", Choice(("none", "half", "full")))
    full = value_claim("occluder_coverage", "full", "", Choice(("none", "half", "full")))
    a, b = draw_pairs(SPACE, half, 40, seed=6), draw_pairs(SPACE, full, 40, seed=6)
    renders_a = {_rendered(r) for pair in a for r in pair}
    assert len(renders_a) == 40 and renders_a == {_rendered(r) for pair in b for r in pair}
    elevation = boundary_claim(boundary_row("camera_elevation", "above", 40.0), "", Range(0.0, 80.0))
    drawn = draw_pairs(SPACE, elevation, 80, seed=6)
    base = {_rendered(r)[:3]: _rendered(r) for pair in a for r in pair}
    shared = [p for p in drawn if _rendered(p[0])[:3] in base]
    assert len(shared) >= 35  # the mug's scenes: the same bases (yaw) as the occluder claims'
    assert all(base[_rendered(p[0])[:3]] in (_rendered(p[0]), _rendered(p[1])) for p in shared)
    assert len({_rendered(r) for pair in drawn for r in pair}) > 80  # and never two pairs on one base


def test_a_twin_keeping_its_bases_value_is_still_uniform_over_its_side() -> None:
    """The inside twin keeps the base's value when it lies inside, else draws one: over many pairs
    each side's values are uniform (chi-square over thirds of the side), the outside's too."""
    from scipy.stats import chisquare

    claim = boundary_claim(boundary_row("camera_elevation", "above", 20.0), "", Range(0.0, 80.0))
    drawn = draw_pairs(SPACE, claim, 3000, seed=8)
    inside = np.array([a["camera_elevation"] for a, _ in drawn])
    outside = np.array([b["camera_elevation"] for _, b in drawn])
    assert chisquare(np.histogram(inside, bins=3, range=(20, 80))[0]).pvalue > 0.001
    assert chisquare(np.histogram(outside, bins=3, range=(0, 20))[0]).pvalue > 0.001
    kept = np.mean([a["camera_elevation"] == b["camera_elevation"] for a, b in drawn])
    assert kept == 0  # the twins always differ in the claim's parameter


def test_a_budget_allots_shared_renders_first_and_stays_within_it() -> None:
    from sweep3d.followups.confirm.run import allotted

    keys = [[("a", "b"), ("c", "d"), ("e", "f")],  # claim 0: two renders a pair
            [("a", "b"), ("c", "d"), ("e", "f")],  # claim 1: the same twins (a blur claim's beside another's)
            [("p", "q"), ("r", "s"), ("t", "u")]]  # claim 2: its own renders
    assert allotted(keys, 0) == [0, 0, 0]
    assert allotted(keys, 2) == [1, 1, 0]  # one pair's renders give two claims a pair each
    assert allotted(keys, 4) == [1, 1, 1]  # then a claim with none before one with one (the root of its pairs)
    assert allotted(keys, 12) == [3, 3, 3]
    assert allotted(keys, 11) == [3, 3, 2]
    for budget in range(13):  # never more distinct renders than the budget, each claim a prefix of its pairs
        counts = allotted(keys, budget)
        assert len({k for group, n in zip(keys, counts) for pair in group[:n] for k in pair}) <= budget


def test_a_budget_buys_whole_the_pairs_a_strong_claim_needs_and_none_for_the_hopeless() -> None:
    """Eighteen claims with no render in common, 100 renders (50 pairs): spread evenly none would
    have the 9 pairs any outcome needs among 18; the strong claims get what brings them near a
    decision, the hopeless one nothing, and renders beyond what is worth one stay unspent."""
    from sweep3d.followups.confirm.run import allotted

    keys = [[(f"{c}a{k}", f"{c}b{k}") for k in range(40)] for c in range(18)]
    weights = [0.9] * 5 + [0.5] * 12 + [0.05]
    counts = allotted(keys, 100, weights)
    strong = [n for n in counts[:5] if n]
    assert len(strong) >= 4 and min(strong) >= 9 and sum(counts) <= 50 and counts[17] == 0, counts
    few = [[(f"{c}a{k}", f"{c}b{k}") for k in range(60)] for c in range(3)]
    capped = allotted(few, 1000, [0.95] * 3)  # each likely decided long before 1000 renders
    assert all(9 <= n < 60 for n in capped) and len({k for g, n in zip(few, capped) for p in g[:n] for k in p}) < 1000


def test_a_scoped_boundary_draws_in_its_object_only() -> None:
    claim = boundary_claim(boundary_row("orientation_yaw", "below", 0.0, "object", "toaster"), "",
                           Range(-180.0, 180.0))
    assert {a["object"] for a, _ in draw_pairs(SPACE, claim, 20, seed=3)} == {"toaster"}


# -- a true region is confirmed; a chance one is not -----------------------------------------------

def test_a_true_region_is_confirmed_in_at_least_95_percent_of_seeds() -> None:
    """Two true regions: a boundary the oracle fails beyond exactly, and a bin of yaw where it fails
    60 % of the time against 15 % elsewhere (a noisy model)."""
    boundary = boundary_claim(boundary_row("camera_elevation", "above", 40.0), "", Range(0.0, 80.0))
    exact = lambda row, rng: row["camera_elevation"] <= 40  # noqa: E731
    assert sum(verdict_of(boundary, exact, s).status == CONFIRMED for s in range(SEEDS)) >= 0.95 * SEEDS
    region = value_claim("orientation_yaw", "80–110", "", Range(-180.0, 180.0), level_value=95.0, width=30.0)

    def noisy(row, rng) -> bool:
        return rng.random() >= (0.6 if 80 <= row["orientation_yaw"] <= 110 else 0.15)
    verdicts = [verdict_of(region, noisy, s) for s in range(SEEDS)]
    assert sum(v.status == CONFIRMED for v in verdicts) >= 0.95 * SEEDS
    assert np.mean([v.difference for v in verdicts]) == pytest.approx(-0.45, abs=0.05)


def test_a_chance_region_significant_in_a_small_discovery_set_is_not_replicated_at_the_stated_rate() -> None:
    """Where nothing matters (the oracle is right 60 % of the time everywhere), discovery sets of
    30 random jobs are searched for an occluder value significantly below the rest (one-sided
    Fisher, p < 0.05 as it would look before any adjustment); each one found is confirmed on the
    default number of fresh pairs. At most ALPHA of them may be called confirmed (with sampling slack)."""
    rng = np.random.default_rng(11)
    options = ("none", "half", "full")
    planted = []
    while len(planted) < 300:
        levels = rng.integers(3, size=30)
        correct = rng.random(30) < 0.6
        for level in range(3):
            inside = levels == level
            p = hypergeom.cdf(correct[inside].sum(), 30, correct.sum(), inside.sum())
            if 0 < inside.sum() < 30 and p < 0.05:
                planted.append(options[level])
                break
    null = lambda row, rng: rng.random() < 0.6  # noqa: E731
    confirmed = 0
    for seed, label in enumerate(planted):
        claim = value_claim("occluder_coverage", label, "", Choice(options))
        verdict = verdict_of(claim, null, 1000 + seed)
        assert verdict.status in (CONFIRMED, NOT_REPLICATED, INCONCLUSIVE)  # one look of 32 pairs bounds little
        confirmed += verdict.status == CONFIRMED
    # exact McNemar is conservative: about 3 % expected; ALPHA + 2.5 standard errors of 300 draws
    assert confirmed / len(planted) <= ALPHA + 2.5 * (ALPHA * (1 - ALPHA) / len(planted)) ** 0.5


# -- the record, as run's findings and the report read it -------------------------------------------

def test_the_report_panel_marks_each_finding_by_its_recorded_verdict(tmp_path) -> None:
    from types import SimpleNamespace

    from sweep3d.cache.store import Store
    from sweep3d.cli.output import UNCONFIRMED_MARK, confirmation_marks
    from sweep3d.followups.confirm.claims import boundary_key, region_key
    from sweep3d.followups.confirm.record import write_verdicts
    from sweep3d.report.panels import confirmations
    from sweep3d.results.summary import Region

    store = Store(tmp_path / "store")
    region = {"column": "occluder_coverage", "label": "half"}
    boundary = boundary_row("camera_elevation", "above", 40.0)
    inputs = SimpleNamespace(store=store, loaded=SimpleNamespace(name="e"),
                             summary=SimpleNamespace(regions=[region], boundaries=[boundary], rules=[]))
    assert confirmations.build(inputs) is None  # nothing confirmed yet: no panel
    (verdict,) = judge([Pairs(both_right=10, inside_wrong=12, inside_right=1, both_wrong=3)])
    write_verdicts(store, "e", {region_key("occluder_coverage", "half"): {"text": "", "verdict": verdict.as_dict()}})
    rows = confirmations.build(inputs)["rows"]
    assert [r["status"] for r in rows] == [CONFIRMED, UNCONFIRMED]
    assert rows[0]["pairs"] == 26 and rows[0]["difference"].startswith("-42 pts")
    assert boundary_key(boundary) == "boundary camera_elevation fails above 40"
    marks = confirmation_marks(store, "e", [Region("occluder_coverage", "half", 0.2, 5, 0.8, 5, -0.6, -0.9, -0.2,
                                                   0.01)], [boundary])
    assert marks[0].startswith(" [confirmed on 26 fresh pairs: -42 pts") and marks[1] == UNCONFIRMED_MARK


def test_a_value_of_an_integer_range_is_drawn_as_the_integer_the_plan_holds() -> None:
    claim = value_claim("scale_steps", "3", "", Range(1.0, 9.0, integer=True), level_value=3.0)
    space = Space(("mug",), ("white",), (Parameter("scale_steps", "scale", "steps", Range(1.0, 9.0, integer=True),
                                                   frozenset({("mug", "white")})),))
    for inside, outside in draw_pairs(space, claim, 20, seed=1):
        assert inside["scale_steps"] == 3 and type(inside["scale_steps"]) is int
        assert outside["scale_steps"] != 3 and type(outside["scale_steps"]) is int


def test_pairs_too_few_for_any_outcome_to_confirm_leave_a_finding_unconfirmed_not_refuted() -> None:
    from sweep3d.results.confirmation import pairs_needed

    for findings in (1, 3, 10):
        n = pairs_needed(findings)
        assert 0.5 ** n * findings < ALPHA <= 0.5 ** (n - 1) * findings  # the fewest with which it can be done
        all_its_way = judge([Pairs(inside_wrong=n)] + [Pairs(both_right=n)] * (findings - 1))
        assert all_its_way[0].status == CONFIRMED
        one_short = judge([Pairs(inside_wrong=n - 1)] + [Pairs(both_right=n - 1)] * (findings - 1))
        # among all of them none could be confirmed: the family is the first few that could, the
        # rest are left out, unconfirmed ("not replicated" would claim what was not tested)
        family = one_short[0].findings
        assert (family < findings or findings == 1) and all(v.status == UNCONFIRMED for v in one_short[family:])
        assert NOT_REPLICATED not in {v.status for v in one_short}
    short = judge([Pairs(inside_wrong=4), Pairs(both_right=4)])  # below the 5 any finding needs alone
    assert {v.status for v in short} == {UNCONFIRMED}


def test_a_finding_too_short_of_pairs_to_be_confirmed_does_not_raise_the_others_bar() -> None:
    """Five pairs all one way (p = 1/32) confirm a finding alone; beside a finding of one pair,
    which no outcome could confirm, Holm over two would miss it (2/32 > 5 %): the short one is
    left out of the family, and stays unconfirmed, not refuted."""
    alone, short = judge([Pairs(inside_wrong=5), Pairs(both_right=1)])
    assert alone.status == CONFIRMED and alone.findings == 1
    assert short.status == UNCONFIRMED and short.p_holm == 1.0 and pairs_to_confirm(short) == 6  # 6 among 2
    # two of five pairs: among two, each would need six; the family is the one of them the order
    # picks (by pairs, then first), whatever their outcomes, and only it can be confirmed
    first, second = judge([Pairs(inside_wrong=5), Pairs(inside_wrong=5)])
    assert (first.status, first.findings, second.status) == (CONFIRMED, 1, UNCONFIRMED)
    assert [v.status for v in judge([Pairs(both_right=5), Pairs(inside_wrong=6)])] == [UNCONFIRMED, CONFIRMED]


@given(st.lists(st.integers(1, 40), min_size=1, max_size=30), st.integers(1, 4))
def test_every_finding_of_holms_family_could_be_confirmed_among_it(counts: list[int], looks: int) -> None:
    share = ALPHA / looks
    family = family_of(counts, share, list(range(len(counts))))
    could = [n for n in counts if n >= pairs_needed(1, share)]
    if could:
        assert family and all(counts[i] >= pairs_needed(len(family), share) for i in family)
        assert all(counts[i] <= min(counts[j] for j in family) for i in range(len(counts)) if i not in family)
    else:
        assert family == list(range(len(counts)))  # none could: all tested, none confirmed


@given(want=st.integers(1, 40), renders=st.integers(2, 10_000), kept=st.floats(0.01, 1.0))
def test_the_renders_advised_give_the_pairs_wanted_at_the_share_kept(want: int, renders: int, kept: float) -> None:
    """Pairs dropped as hidden or invalid are lost in proportion: the advice scales with the pairs
    a run of ``renders`` kept, is even, and is above what was given whenever it gave too few."""
    from sweep3d.results.confirmation import renders_for

    got = max(1, min(renders // 2, int(kept * renders // 2)))
    advised = renders_for(want, got, renders)
    assert advised % 2 == 0 and advised >= 2 * want
    assert got * advised / renders >= want  # at the yield of this run, enough pairs
    if got < want:
        assert advised > renders  # never "--renders 14 or more" to one who gave 16
    if got == renders // 2 and renders % 2 == 0:  # nothing dropped: two renders a pair, as before
        assert advised == 2 * want

