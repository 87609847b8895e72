"""Whether a finding replicates on fresh renders: the statistics of ``sweep3d confirm``, pure.

A finding (a failure mode ``occluder = half``, a boundary ``camera_elevation fails below 12``)
names a *region* of the parameters where the model does worse than outside it. ``confirm``
draws fresh configurations in **twins**: one inside the region and one outside, with the same
object, environment and value of every other parameter (see :mod:`sweep3d.followups.confirm.draw`), none
of them a job the finding was discovered on. Each twin pair ends in one of four cells; only the
discordant ones carry evidence (the pair's other parameters, shared, cancel out):

- ``inside_wrong``: wrong inside, right outside (the finding's direction);
- ``inside_right``: right inside, wrong outside (against it).

**Test**: McNemar's exact test, one-sided: under "no effect" each discordant pair goes either way
with probability 1/2, so the p-value is P(X >= inside_wrong), X ~ Binomial(discordant, 1/2).
Fresh data only: nothing the discovery saw enters it, so it is not biased by having picked the
finding as the worst of many. The p-values of the findings confirmed together are adjusted by
Holm's method, and a finding is **confirmed** when its adjusted p < the look's share of
:data:`ALPHA`.

**Sized to decide** (issue 43): ``confirm`` may look at a finding's pairs several times, adding
fresh pairs between looks (the pairs doubling, :func:`planned_looks`). Error control over the
repeated looks: Bonferroni alpha spending, :data:`ALPHA` split evenly over the ``K`` planned looks.
Each look confirms by Holm at ``ALPHA / K`` over the findings still open, so the chance that *any*
finding without a real effect is called confirmed, over all looks, is at most 5 % (the exact test
is conservative: below 5 % in practice). A finding is **not replicated** only when its effect is
bounded: the look's ``1 - ALPHA / K`` interval of the difference lies above ``-FUTILITY`` (the
region costs less than :data:`FUTILITY`, 10 points, of accuracy; a real effect that large is called
not replicated with probability at most 2.5 %). Otherwise it stays open for the next look, and
after the last it is **inconclusive**: neither an effect nor its absence was shown. With too few
pairs for any outcome to confirm it (even every discordant pair its way: 2^-n times the findings
tested together is not below the look's alpha) it stays **unconfirmed**, and :func:`pairs_needed`
says how many would do.

**Effect**: the fresh accuracy inside less outside, ``(inside_right - inside_wrong) / pairs``, with
Newcombe's hybrid score interval for paired proportions (his method 10, from the two Wilson
intervals and the pairs' correlation), at the look's ``1 - ALPHA / K`` (95 % with one look).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass
from statistics import NormalDist
from typing import Callable, Iterable, Mapping, Sequence

#: The family-wise error rate of one confirmation (Holm over its findings), one-sided.
ALPHA = 0.05
#: Fresh renders per finding by default (32 twin pairs): a region failing 60 % of the time against
#: 15 % elsewhere is confirmed in about 98 % of seeds (tests/results/test_confirm_statistics.py).
DEFAULT_RENDERS = 64
Z95 = 1.959963984540054

#: The effect below which a finding does not matter: "not replicated" says the region costs less
#: than this share of accuracy (10 points), beyond doubt.
FUTILITY = 0.10
#: ``--max-renders``'s default: the most fresh renders per finding over all looks.
DEFAULT_MAX_RENDERS = 256

CONFIRMED = "confirmed"
NOT_REPLICATED = "not replicated"
INCONCLUSIVE = "inconclusive"  # the last look came and neither the effect nor its absence was shown
OPEN = "open"  # an earlier look that decided nothing: more pairs come
UNCONFIRMED = "unconfirmed"  # not tested (yet), or no fresh pair could be drawn


@dataclass(frozen=True)
class Pairs:
    """The fresh twin pairs of one finding, by cell (inside's verdict, outside's verdict)."""

    both_right: int = 0
    inside_wrong: int = 0  # wrong inside, right outside: the finding's direction
    inside_right: int = 0  # right inside, wrong outside: against it
    both_wrong: int = 0

    @property
    def n(self) -> int:
        return self.both_right + self.inside_wrong + self.inside_right + self.both_wrong

    @property
    def accuracy_inside(self) -> float | None:
        return (self.both_right + self.inside_right) / self.n if self.n else None

    @property
    def accuracy_outside(self) -> float | None:
        return (self.both_right + self.inside_wrong) / self.n if self.n else None


def tally(outcomes: Iterable[tuple[bool, bool]]) -> Pairs:
    """The :class:`Pairs` of (inside correct, outside correct) per twin pair."""
    cells = {(True, True): 0, (True, False): 0, (False, True): 0, (False, False): 0}
    for inside, outside in outcomes:
        cells[(bool(inside), bool(outside))] += 1
    return Pairs(both_right=cells[True, True], inside_right=cells[True, False], inside_wrong=cells[False, True],
                 both_wrong=cells[False, False])


def mcnemar_one_sided(worse: int, better: int) -> float:
    """P(X >= worse) for X ~ Binomial(worse + better, 1/2): exact, in integers (1.0 with no
    discordant pair)."""
    n = worse + better
    if n == 0 or worse == 0:
        return 1.0
    return min(1.0, sum(math.comb(n, k) for k in range(worse, n + 1)) / 2 ** n)


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of k/n (n > 0) at normal quantile ``z`` (95 % by default), clamped
    as the views' ``wilson_low``/``_high``."""
    p = k / n
    z2 = z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z * math.sqrt(max(p * (1 - p) / n + z2 / (4 * n * n), 0.0)) / (1 + z2 / n)
    return min(p, max(0.0, centre - half)), max(p, min(1.0, centre + half))


def paired_difference_interval(pairs: Pairs, z: float = Z95) -> tuple[float, float] | None:
    """Newcombe's (1998) method-10 interval (95 % by default; ``z`` its normal quantile) of accuracy
    inside less outside on paired data; None without pairs. Always within [-1, 1] and around the
    difference."""
    n = pairs.n
    if n == 0:
        return None
    a, b, c, d = pairs.both_right, pairs.inside_right, pairs.inside_wrong, pairs.both_wrong
    p1, p2 = (a + b) / n, (a + c) / n
    l1, u1 = wilson(a + b, n, z)
    l2, u2 = wilson(a + c, n, z)
    denominator = (a + b) * (c + d) * (a + c) * (b + d)
    phi = (a * d - b * c) / math.sqrt(denominator) if denominator > 0 else 0.0
    difference = p1 - p2
    down = math.sqrt(max((p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2, 0.0))
    up = math.sqrt(max((u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2, 0.0))
    return max(-1.0, difference - down), min(1.0, difference + up)


@dataclass(frozen=True)
class Verdict:
    """What the fresh pairs of one finding say (see the module)."""

    status: str  # CONFIRMED, NOT_REPLICATED, INCONCLUSIVE, OPEN (a look before the last) or UNCONFIRMED
    pairs: int
    both_right: int
    inside_wrong: int
    inside_right: int
    both_wrong: int
    accuracy_inside: float | None
    accuracy_outside: float | None
    difference: float | None
    difference_low: float | None
    difference_high: float | None
    p_value: float  # McNemar's exact one-sided
    p_holm: float  # adjusted over the findings confirmed together
    findings: int  # how many were confirmed together (Holm's family)
    look: int = 1  # the look that gave this verdict
    looks: int = 1  # the planned looks (alpha split evenly over them)
    futility: float = FUTILITY  # the effect bounded below for "not replicated"
    in_family: bool = True  # whether it was in Holm's family (False: too few pairs, see family_of)

    @property
    def decided(self) -> bool:
        """Whether more pairs would change nothing (confirmed, or its effect bounded)."""
        return self.status in (CONFIRMED, NOT_REPLICATED)

    def as_dict(self) -> dict:
        return asdict(self)


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjustment of ``p_values`` (same order), monotone, at most 1."""
    m = len(p_values)
    order = sorted(range(m), key=lambda i: p_values[i])
    out = [1.0] * m
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p_values[i]))
        out[i] = running
    return out


def planned_looks(first: int, cap: int) -> int:
    """How many looks at most: the pairs double from ``first`` until they reach ``cap``."""
    looks, size = 1, max(1, first)
    while size < cap:
        size *= 2
        looks += 1
    return looks


def look_z(looks: int, alpha: float = ALPHA) -> float:
    """The normal quantile of a two-sided interval at ``1 - alpha / looks`` (Bonferroni)."""
    return NormalDist().inv_cdf(1 - alpha / (2 * max(1, looks)))


def first_look(pairs: int, least: int) -> int:
    """The first look's pairs when the looks double up to ``pairs`` (what a budget pays each
    finding): ``pairs`` halved, rounded up, while the half is still ``least`` or more. A budget
    too small for two looks of ``least`` pairs gets one look, so no share of the error rate goes
    to a look the budget could not pay for."""
    first = max(1, pairs)
    while (first + 1) // 2 >= max(1, least):
        first = (first + 1) // 2
    return first


def family_of(counts: Sequence[int], alpha: float, ids: Sequence[int]) -> list[int]:
    """Holm's family among findings with ``counts`` pairs (``ids`` theirs): the most findings m such
    that each could be confirmed among m (``pairs_needed(m, alpha)`` pairs each), those with the
    most pairs, the first on a tie; all of them when not even one could. It reads how many pairs
    each finding has, never how they came out."""
    order = sorted(range(len(counts)), key=lambda j: (-counts[j], j))
    family = max((m for m in range(1, len(order) + 1) if counts[order[m - 1]] >= pairs_needed(m, alpha)), default=0)
    kept = set(order[:family]) if family else set(order)
    return [ids[j] for j in range(len(counts)) if j in kept]


def pairs_to_confirm(verdict: "Verdict", alpha: float = ALPHA) -> int:
    """The fewest pairs with which ``verdict``'s finding could be confirmed: among its family, or,
    when it was left out for want of pairs, joining it."""
    share = alpha / max(1, verdict.looks)
    return pairs_needed(verdict.findings + (not verdict.in_family), share)


def pairs_needed(findings: int, alpha: float = ALPHA) -> int:
    """The fewest twin pairs with which a finding tested among ``findings`` can be confirmed at
    all: every pair discordant its way gives p = 2^-n, which Holm multiplies by up to ``findings``."""
    return max(1, math.floor(math.log2(max(findings, 1) / alpha)) + 1)


def renders_for(want: int, got: int, renders: int) -> int:
    """The ``--renders`` (even) that would give ``want`` twin pairs where ``renders`` gave ``got``:
    pairs dropped (a hidden object, an invalid prediction) are lost in the same proportion, so
    the advice scales with what was kept, never below two renders a pair."""
    wanted = max(2 * want, math.ceil(want * renders / got)) if got > 0 else 2 * want
    return wanted + wanted % 2


def judge(findings: Sequence[Pairs], alpha: float = ALPHA, look: int = 1, looks: int = 1,
          futility: float = FUTILITY) -> list[Verdict]:
    """One :class:`Verdict` per finding's fresh pairs at look ``look`` of ``looks``, tested together
    (Holm at ``alpha / looks`` over those with enough pairs): confirmed, not replicated (the effect
    bounded below ``futility``), and otherwise open, or inconclusive at the last look. Holm's
    family is :func:`family_of`'s: a finding too short of pairs for any outcome to confirm it is
    left out (counting it would only raise the others' bar). The family depends on how many pairs
    each finding has, never on whether its twins came out right or wrong."""
    share = alpha / max(1, looks)
    z = look_z(looks, alpha)
    tested = [i for i, pairs in enumerate(findings) if pairs.n]
    tested = family_of([findings[i].n for i in tested], share, tested)
    raw = {i: mcnemar_one_sided(pairs.inside_wrong, pairs.inside_right) for i, pairs in enumerate(findings) if pairs.n}
    adjusted = dict(zip(tested, holm([raw[i] for i in tested])))
    verdicts = []
    for i, pairs in enumerate(findings):
        p = raw.get(i, 1.0)
        q = adjusted.get(i, 1.0)
        interval = paired_difference_interval(pairs, z)
        too_few = i not in adjusted or pairs.n < pairs_needed(len(tested), share)  # no outcome could confirm it
        if not pairs.n:
            status = UNCONFIRMED
        elif q < share:
            status = CONFIRMED
        elif interval is not None and interval[0] > -futility:
            status = NOT_REPLICATED
        elif too_few and look >= looks:
            status = UNCONFIRMED
        else:
            status = INCONCLUSIVE if look >= looks else OPEN
        inside, outside = pairs.accuracy_inside, pairs.accuracy_outside
        verdicts.append(Verdict(
            status, pairs.n, pairs.both_right, pairs.inside_wrong, pairs.inside_right, pairs.both_wrong, inside,
            outside, None if inside is None or outside is None else inside - outside,
            None if interval is None else interval[0], None if interval is None else interval[1], p, q, len(tested),
            look, looks, futility, i in adjusted))
    return verdicts


def sequential(findings: int, first: int, cap: int, observe: Callable[[Mapping[int, int]], Mapping[int, Pairs]],
               alpha: float = ALPHA, futility: float = FUTILITY, together: bool = True,
               caps: Sequence[int] | None = None) -> list[Verdict]:
    """Judge ``findings`` in looks: ``observe({finding: pairs wanted})`` gives each open finding's
    fresh pairs so far (cumulative; fewer when no more can be drawn), the pairs doubling from
    ``first`` to ``cap``. A finding leaves once decided (confirmed, or its effect bounded), or when
    no more pairs come; the rest are inconclusive after the last look. ``together``: Holm over the
    open findings at each look (else each judged alone, Bonferroni over the looks only). ``caps``
    (each judged alone): each finding's own most pairs; its looks are then only those that give it
    more pairs, the error rate split over them alone (a finding of 8 pairs where the looks go to 23
    has one look, at the whole rate)."""
    sizes, size = [], max(1, first)
    while size < max(cap, first):
        sizes.append(size)
        size *= 2
    sizes.append(max(cap, first))
    looks = len(sizes)
    own = [sorted({min(s, c) for s in sizes}) for c in caps] if caps is not None and not together else None
    final: dict[int, Verdict] = {}
    seen: dict[int, int] = {}
    for look, size in enumerate(sizes, 1):
        open_ = [i for i in range(findings) if i not in final]
        if own is not None:  # a finding whose pairs this look would not add to waits for a look that does
            open_ = [i for i in open_ if look == 1 or min(size, caps[i]) > min(sizes[look - 2], caps[i])]
        if not open_:
            if len(final) == findings:
                break
            continue
        got = observe({i: size for i in open_})
        if own is None:
            verdicts = (judge([got[i] for i in open_], alpha, look, looks, futility) if together
                        else [judge([got[i]], alpha, look, looks, futility)[0] for i in open_])
        else:
            verdicts = [judge([got[i]], alpha, own[i].index(min(size, caps[i])) + 1, len(own[i]), futility)[0]
                        for i in open_]
        for i, verdict in zip(open_, verdicts):
            stalled = look > 1 and verdict.pairs <= seen.get(i, 0)  # no more pairs could be drawn
            seen[i] = verdict.pairs
            if verdict.status == OPEN and stalled:
                verdict = dataclasses.replace(verdict, status=INCONCLUSIVE)
            if verdict.status != OPEN:
                final[i] = verdict
    return [final[i] for i in range(findings)]
