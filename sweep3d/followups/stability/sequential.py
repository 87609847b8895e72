"""The stability check's sequential design: add images in rounds until every margin bin's flip
rate is decided against the fragile rule, or the cap is reached.

The rule (:mod:`sweep3d.results.fragile`) calls a bin's margins fragile when its flip rate is
:data:`~sweep3d.results.fragile.FLIP_RATE` (1 in 10) or more beyond reasonable doubt. A fixed
sample leaves bins whose rate is near 1 in 10 *undecided*: at 64 images a bin that flips 15–25 %
of the time holds about 9 images and cannot pass the rule, so a count read from it is a lower
bound. Here a bin is

- *fragile* once its interval lies at or above 1 in 10,
- *not fragile* once its interval lies below it,
- *undecided* otherwise,

and only undecided bins are given more images, the sample (cumulative) doubling each round from
``--sample`` up to ``--max-sample``.

Error control over the repeated looks: Bonferroni over the planned looks. With ``K`` rounds at
most (:func:`planned_looks`), every look uses the Wilson interval at confidence ``1 - ALPHA / K``,
so the chance that any of a bin's looks excludes its true flip rate, and so the chance that the
bin is decided the wrong way, is at most ``ALPHA`` (5 %) per bin, whenever the check stops. (Per
bin: the seven bins are not corrected against each other.)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

from sweep3d.results import confirmation_wilson, look_z, planned_looks

__all__ = ["look_z", "planned_looks"]  # the looks as confirm counts them, for the check and its tests

#: The error rate of one bin's decision over all of its looks (split evenly over the planned looks).
ALPHA = 0.05
#: ``--max-sample``'s default: the most images one check re-infers per model.
DEFAULT_MAX_SAMPLE = 1024
#: No estimate of a deciding sample is made beyond this many images of one bin.
MOST_NEEDED = 10_000_000

FRAGILE, ROBUST, UNDECIDED, UNCHECKED = "fragile", "not fragile", "undecided", "not checked"


def round_sizes(first: int, cap: int) -> list[int]:
    """The cumulative sample each round aims at: ``first``, doubling, the last ``cap``."""
    sizes, size = [], max(1, first)
    while size < cap:
        sizes.append(size)
        size *= 2
    return [*sizes, max(cap, first)]


def wilson(flips: int, n: int, z: float) -> tuple[float, float]:
    """The Wilson score interval of ``flips`` of ``n`` at normal quantile ``z``; (0, 1) without images."""
    return confirmation_wilson(flips, n, z) if n > 0 else (0.0, 1.0)


def decide(flips: int, n: int, looks: int, rate: float | None = None) -> tuple[str, float, float]:
    """A bin's decision against the rule after ``flips`` of ``n``: (decision, low, high), the
    interval at ``1 - ALPHA / looks``. Fragile needs a flip (as the rule does); a bin without
    images is not checked (it cannot set the threshold)."""
    from sweep3d.results import FLIP_RATE

    rate = FLIP_RATE if rate is None else rate
    low, high = wilson(flips, n, look_z(looks))
    if n <= 0:
        return UNCHECKED, low, high
    if flips > 0 and low >= rate:
        return FRAGILE, low, high
    if high < rate:
        return ROBUST, low, high
    return UNDECIDED, low, high


def needed(flips: int, n: int, looks: int, rate: float | None = None) -> int | None:
    """About how many images of a bin would decide it if it kept flipping at ``flips / n``: the
    least ``m`` whose interval at that rate excludes the rule's. None without images, or beyond
    :data:`MOST_NEEDED` (a rate that near 1 in 10 is not decided by any sample worth taking)."""
    if n <= 0:
        return None
    observed = flips / n

    def decides(m: int) -> bool:
        return decide(round(observed * m), m, looks, rate)[0] != UNDECIDED

    high = max(n, 1)
    while not decides(high):
        high *= 2
        if high > MOST_NEEDED:
            return None
    low = max(1, high // 2)
    while low < high:  # the least m that decides, between the last two doublings
        middle = (low + high) // 2
        if decides(middle):
            high = middle
        else:
            low = middle + 1
    return high


def allot(taken: Sequence[int], pools: Sequence[int], open_bins: set[int], room: int) -> list[int]:
    """How many images each bin has once ``room`` more are spread over ``open_bins``: the bins take
    turns, lowest first, one image each, while they have images left (``pools``)."""
    out = list(taken)
    while room > 0:
        moved = False
        for b in sorted(open_bins):
            if room > 0 and out[b] < pools[b]:
                out[b] += 1
                room -= 1
                moved = True
        if not moved:
            break
    return out


@dataclass
class Rounds:
    """Where a sequential check stopped and what it decided."""

    looks: int  # planned (the Bonferroni split)
    rounds: int  # taken
    taken: list[int]  # images per bin asked for
    counts: list[tuple[int, int]]  # (n, flips) per bin at the last look
    decisions: list[tuple[str, float, float]] = field(default_factory=list)
    stopped: str = ""  # "decided", "cap" or "exhausted"
    pools: list[int] = field(default_factory=list)  # the run's images per bin (by its stored margin)

    @property
    def sample(self) -> int:
        return sum(self.taken)

    def undecided(self) -> list[int]:
        return [b for b, (d, _, _) in enumerate(self.decisions) if d == UNDECIDED]


def run_rounds(pools: Sequence[int], first: int, cap: int,
               observe: Callable[[list[int]], list[tuple[int, int]]]) -> Rounds:
    """Run the rounds: ``observe(taken)`` checks ``taken[b]`` images of each bin ``b`` (cumulative,
    the earlier ones already checked) and returns each bin's (images, flips) as the views count
    them. Stops once every bin is decided, the cap is reached, or no undecided bin has images left."""
    cap = max(cap, first)
    sizes = round_sizes(first, cap)
    looks = len(sizes)
    taken = [0] * len(pools)
    open_bins = set(range(len(pools)))
    state = Rounds(looks, 0, taken, [], pools=list(pools))
    for size in sizes:
        grown = allot(taken, pools, open_bins, size - sum(taken))
        if state.rounds and grown == taken:
            state.stopped = "exhausted"
            return state
        taken = grown
        state.counts = observe(taken)
        state.rounds += 1
        state.taken = taken
        state.decisions = [decide(flips, n, looks) for n, flips in state.counts]
        pending = {b for b, (d, _, _) in enumerate(state.decisions)
                   if d == UNDECIDED or (d == UNCHECKED and taken[b] < pools[b])}
        open_bins = {b for b in pending if taken[b] < pools[b]}
        if not pending:
            state.stopped = "decided"
            return state
        if not open_bins:
            state.stopped = "exhausted"
            return state
    state.stopped = "cap"
    return state


def threshold_range(uppers: Sequence[float], decisions: Sequence[tuple[str, float, float]]) -> tuple[float, float]:
    """The fragile threshold as the undecided bins may yet fall: (every undecided bin not fragile,
    every undecided bin fragile). Equal once every bin is decided."""
    low = max((u for u, (d, _, _) in zip(uppers, decisions) if d == FRAGILE), default=0.0)
    high = max((u for u, (d, _, _) in zip(uppers, decisions) if d == UNDECIDED), default=0.0)
    return low, max(low, high)
