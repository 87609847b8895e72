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
Holm's method, and a finding is **confirmed** when its adjusted p < :data:`ALPHA`: the chance that
*any* finding without a real effect is called confirmed in one ``confirm`` is at most 5 % (the
exact test is conservative: below 5 % in practice). Otherwise it is **not replicated** (which does
not prove there is no effect: a small one needs more pairs) — unless its pairs were too few for
any outcome to confirm it (even every discordant pair its way: 2^-n times the findings tested
together is not below :data:`ALPHA`); it then stays **unconfirmed**, and :func:`pairs_needed` says
how many would do.

**Effect**: the fresh accuracy inside less outside, ``(inside_right - inside_wrong) / pairs``, with
Newcombe's hybrid score interval for paired proportions (his method 10, from the two Wilson
intervals and the pairs' correlation), 95 %, unadjusted.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Iterable, Sequence

#: The family-wise error rate of one confirmation (Holm over its findings), one-sided.
ALPHA = 0.05
#: Fresh renders per finding by default (32 twin pairs): a region failing 60 % of the time against
#: 15 % elsewhere is confirmed in about 98 % of seeds (tests/results/test_confirm_statistics.py).
DEFAULT_RENDERS = 64
Z95 = 1.959963984540054

CONFIRMED = "confirmed"
NOT_REPLICATED = "not replicated"
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


def wilson(k: int, n: int) -> tuple[float, float]:
    """The 95 % Wilson score interval of k/n (n > 0), clamped as the views' ``wilson_low``/``_high``."""
    p = k / n
    z2 = Z95 * Z95
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = Z95 * math.sqrt(max(p * (1 - p) / n + z2 / (4 * n * n), 0.0)) / (1 + z2 / n)
    return min(p, max(0.0, centre - half)), max(p, min(1.0, centre + half))


def paired_difference_interval(pairs: Pairs) -> tuple[float, float] | None:
    """Newcombe's (1998) method-10 95 % interval of accuracy inside less outside on paired data;
    None without pairs. Always within [-1, 1] and around the difference."""
    n = pairs.n
    if n == 0:
        return None
    a, b, c, d = pairs.both_right, pairs.inside_right, pairs.inside_wrong, pairs.both_wrong
    p1, p2 = (a + b) / n, (a + c) / n
    l1, u1 = wilson(a + b, n)
    l2, u2 = wilson(a + c, n)
    denominator = (a + b) * (c + d) * (a + c) * (b + d)
    phi = (a * d - b * c) / math.sqrt(denominator) if denominator > 0 else 0.0
    difference = p1 - p2
    down = math.sqrt(max((p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2, 0.0))
    up = math.sqrt(max((u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2, 0.0))
    return max(-1.0, difference - down), min(1.0, difference + up)


@dataclass(frozen=True)
class Verdict:
    """What the fresh pairs of one finding say (see the module)."""

    status: str  # CONFIRMED, NOT_REPLICATED or UNCONFIRMED (no pair)
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


def judge(findings: Sequence[Pairs], alpha: float = ALPHA) -> list[Verdict]:
    """One :class:`Verdict` per finding's fresh pairs, tested together (Holm over those with pairs)."""
    tested = [i for i, pairs in enumerate(findings) if pairs.n]
    raw = [mcnemar_one_sided(findings[i].inside_wrong, findings[i].inside_right) for i in tested]
    adjusted = dict(zip(tested, holm(raw)))
    verdicts = []
    for i, pairs in enumerate(findings):
        p = raw[tested.index(i)] if i in adjusted else 1.0
        q = adjusted.get(i, 1.0)
        interval = paired_difference_interval(pairs)
        too_few = pairs.n < pairs_needed(len(tested), alpha)  # no outcome of so few pairs could confirm it
        status = UNCONFIRMED if not pairs.n or too_few else CONFIRMED if q < alpha else NOT_REPLICATED
        inside, outside = pairs.accuracy_inside, pairs.accuracy_outside
        verdicts.append(Verdict(
            status, pairs.n, pairs.both_right, pairs.inside_wrong, pairs.inside_right, pairs.both_wrong, inside,
            outside, None if inside is None or outside is None else inside - outside,
            None if interval is None else interval[0], None if interval is None else interval[1], p, q, len(tested)))
    return verdicts
