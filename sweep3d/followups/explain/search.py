"""The nearest configuration where the model is right, for each failure: a pure search.

It knows nothing of rendering: configurations are points of a scene's unit cube
(:class:`~sweep3d.spec.space.Point`), and an *oracle* answers, for a batch of them, whether the
model is right there. Its runner (:mod:`sweep3d.followups.explain.run`) answers through the stages, so
every probe is cached like any other job; tests answer with a synthetic function.

For each failure the search walks *rays* out of its point and keeps the nearest right one:

* one parameter at a time (phase 1): a range both ways, by doubling steps until a probe is right
  (``first_step``, twice that, … up to the range's end; half a turn either way for a range that
  covers a whole period) and then bisection between the last wrong and the first right probe
  until they are ``resolution`` apart, as the boundary policy narrows a step; a list to its other
  options, nearest first;
* then pairs of parameters (phase 2): two ranges along the four diagonals, a range with each
  other option of a list, two lists' options together.

Distance is Euclidean over each parameter's share of its range (a unit coordinate; for a list,
how many places an option moves over the list's length less one), so a fix that moves yaw by a
tenth of its range and nothing else costs 0.1, and two moves of 0.1 cost 0.14. A ray stops as
soon as it cannot beat the nearest fix already found, so pairs cost little where a single
parameter fixes the failure nearby. Every failure's rays advance together, one probe each per
round, so the oracle is asked in batches.

A *budget* bounds the probes charged (``free`` says which are not: the run's own jobs); the
failures are taken in a seeded order, a few at a time, and a failure whose next probes no longer
fit is stopped with the nearest fix it had (``complete`` false), or left out when its first
probes do not fit (not reached); then no later failure is taken, so the failures reached are the
first of the seeded order, a random sample of them all. The same failures, seed,
budget and verdicts give the same probes in the same order, so a search killed and run again
replays what is cached and goes on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Iterator, Sequence

import numpy as np

from sweep3d.spec import Point

Scene = tuple[str, str]
#: Whether the model is right (valid, evaluable and correct) at each configuration asked.
Oracle = Callable[[list["Config"]], list[bool]]


@dataclass(frozen=True)
class Axis:
    """One parameter a scene leaves open. ``index``: its place in ``Point.unit`` (a range) or
    ``Point.choice`` (a list); ``size``: a list's number of options."""

    name: str
    kind: str  # "range" or "list"
    index: int
    wraps: bool = False
    size: int = 0


@dataclass(frozen=True)
class Config:
    """One configuration: a scene and a point of its unit cube."""

    scene: Scene
    point: Point


@dataclass(frozen=True)
class Move:
    """One parameter's change from the failure to its fix, as a signed share of its range."""

    axis: str
    share: float


@dataclass(frozen=True)
class Fix:
    """What the search found for one failure: the nearest right configuration (None if no ray
    reached one), the moves that make it, their distance, how many probes it asked for, and
    whether it ran to the end (false: the budget stopped it).

    The rest is filled in once the verdicts' margins are read (:mod:`.further`): the margin at
    the fix, whether the stability check's rule calls it fragile (None: no check, or no margin),
    how many probes went past a fragile fix along its change, and ``nearest``, the fragile
    nearest fix that a sturdier one further along replaced."""

    failure: Config
    fix: Config | None
    moves: tuple[Move, ...]
    distance: float
    probes: int
    complete: bool
    margin: float | None = None
    fragile: bool | None = None
    further: int = 0
    nearest: Fix | None = None


@dataclass
class _Ray:
    """A line out of a failure's point: ``fixed`` list moves, and range axes each moved by ±t."""

    fixed: tuple[tuple[Axis, int], ...]  # (list axis, option index moved to)
    ranges: tuple[tuple[Axis, int], ...]  # (range axis, +1 or -1)
    t_max: float
    base: float  # distance of the fixed moves alone
    lo: float = 0.0  # the farthest t known wrong
    hi: float | None = None  # the nearest t known right
    done: bool = False

    def distance(self, t: float) -> float:
        return math.sqrt(self.base ** 2 + len(self.ranges) * t * t)


@dataclass
class _Search:
    """One failure's search: its rays by phase, and the nearest fix so far."""

    failure: Config
    axes: list[Axis]
    resolution: float
    first_step: float
    best: tuple[float, Config, tuple[Move, ...]] | None = None
    probes: int = 0
    phase: int = 0
    rays: list[_Ray] = field(default_factory=list)

    def start(self) -> None:
        self.phase = 1
        self.rays = list(_single_rays(self.failure.point, self.axes))

    def config(self, ray: _Ray, t: float) -> Config:
        unit, choice = list(self.failure.point.unit), list(self.failure.point.choice)
        for axis, option in ray.fixed:
            choice[axis.index] = option
        for axis, sign in ray.ranges:
            u = unit[axis.index] + sign * t
            unit[axis.index] = u % 1.0 if axis.wraps else min(max(u, 0.0), 1.0)
        return Config(self.failure.scene, Point(tuple(unit), tuple(choice)))

    def moves(self, ray: _Ray, t: float) -> tuple[Move, ...]:
        out = [Move(axis.name, (option - self.failure.point.choice[axis.index]) / (axis.size - 1))
               for axis, option in ray.fixed]
        out += [Move(axis.name, sign * t) for axis, sign in ray.ranges]
        return tuple(sorted(out, key=lambda m: m.axis))

    def next_t(self, ray: _Ray) -> float | None:
        """The ray's next probe, or None when it is done (found, exhausted, or beaten)."""
        limit = self.best[0] if self.best else math.inf
        if not ray.ranges:  # list moves only: one probe
            return None if ray.done or ray.base >= limit else 0.0
        if ray.hi is not None:
            if ray.hi - ray.lo <= self.resolution or ray.distance(ray.lo) >= limit:
                return None
            return (ray.lo + ray.hi) / 2
        t = min(ray.t_max, self.first_step if ray.lo == 0.0 else 2 * ray.lo)
        reach = math.sqrt(max(limit ** 2 - ray.base ** 2, 0.0) / len(ray.ranges)) if limit < math.inf else math.inf
        if reach <= ray.lo:
            return None
        if t >= reach:  # no farther than the nearest fix allows; bisection will show which side
            t = (ray.lo + reach) / 2 if reach - ray.lo > self.resolution else None
        return None if t is None or t <= ray.lo else t

    def requests(self) -> list[tuple[_Ray, float, Config]]:
        """This round's probes: one per live ray; moves to the next phase when none is left."""
        while self.phase in (1, 2):
            out = []
            for ray in self.rays:
                t = self.next_t(ray)
                if t is None:
                    ray.done = True
                else:
                    out.append((ray, t, self.config(ray, t)))
            if out:
                return out
            self.phase += 1
            self.rays = list(_pair_rays(self.failure.point, self.axes, self.best)) if self.phase == 2 else []
        return []

    def answer(self, ray: _Ray, t: float, config: Config, right: bool) -> None:
        if not ray.ranges:
            ray.done = True
        elif right:
            ray.hi = t
        else:
            ray.lo = t
            if t >= ray.t_max:
                ray.done = True
        if right:
            d = ray.distance(t)
            if self.best is None or d < self.best[0] - 1e-12:
                self.best = (d, config, self.moves(ray, t))

    def result(self, complete: bool) -> Fix:
        if self.best is None:
            return Fix(self.failure, None, (), math.inf, self.probes, complete)
        d, config, moves = self.best
        return Fix(self.failure, config, moves, d, self.probes, complete)


def _single_rays(point: Point, axes: Sequence[Axis]) -> Iterator[_Ray]:
    for axis in axes:
        if axis.kind == "range":
            for sign in (1, -1):
                yield _Ray((), ((axis, sign),), _t_max(point, axis, sign), 0.0)
        else:
            yield from (_Ray(((axis, option),), (), 0.0, share) for option, share in _options(point, axis))


def _pair_rays(point: Point, axes: Sequence[Axis], best) -> Iterator[_Ray]:
    limit = best[0] if best else math.inf
    for i, a in enumerate(axes):
        for b in axes[i + 1:]:
            if a.kind == "range" and b.kind == "range":
                for sa in (1, -1):
                    for sb in (1, -1):
                        yield _Ray((), ((a, sa), (b, sb)), min(_t_max(point, a, sa), _t_max(point, b, sb)), 0.0)
            elif a.kind == "list" and b.kind == "list":
                for oa, share_a in _options(point, a):
                    for ob, share_b in _options(point, b):
                        base = math.hypot(share_a, share_b)
                        if base < limit:
                            yield _Ray(((a, oa), (b, ob)), (), 0.0, base)
            else:
                listed, ranged = (a, b) if a.kind == "list" else (b, a)
                for option, share in _options(point, listed):
                    if share < limit:
                        for sign in (1, -1):
                            yield _Ray(((listed, option),), ((ranged, sign),), _t_max(point, ranged, sign), share)


def _options(point: Point, axis: Axis) -> list[tuple[int, float]]:
    """A list's other options with their share of its length, nearest first (lower first on a tie)."""
    here = point.choice[axis.index]
    others = [o for o in range(axis.size) if o != here]
    return sorted(((o, abs(o - here) / (axis.size - 1)) for o in others), key=lambda x: (x[1], x[0]))


def _t_max(point: Point, axis: Axis, sign: int) -> float:
    """How far a range can move that way: to its end, or half a turn for one that wraps."""
    if axis.wraps:
        return 0.5
    u = point.unit[axis.index]
    return 1.0 - u if sign > 0 else u


@dataclass
class Progress:
    """What the search has done so far, for a progress line."""

    failures: int  # to search
    started: int = 0
    finished: int = 0
    found: int = 0
    probes: int = 0  # asked of the oracle (distinct)
    charged: int = 0  # of which counted against the budget
    rounds: int = 0


def explain(failures: Sequence[Config], axes: Callable[[Scene], list[Axis]], oracle: Oracle, *,
            budget: int | None = None, seed: int = 0, free: Callable[[Config], bool] = lambda c: False,
            resolution: float = 1 / 64, first_step: float = 1 / 16, concurrent: int = 16,
            on_round: Callable[[Progress], None] | None = None) -> list[Fix]:
    """The nearest fix of each failure searched, in the seeded order they were taken.

    Args:
        failures: the configurations where the model is wrong.
        axes: each scene's open parameters.
        oracle: whether the model is right at each configuration of a batch (asked once per config).
        budget: the most configurations charged (None: no limit); a failure whose next probes do
            not fit is stopped with the nearest fix it had, and left out if it had none yet.
        free: configurations that cost nothing (already evaluated elsewhere).
        resolution: bisection stops when a wrong and a right probe are this close (share of range).
        first_step: the first probe's distance along a range (then doubling).
        concurrent: failures searched together (more: bigger batches for the oracle).
        on_round: called after each round with the counts so far.
    """
    order = [failures[i] for i in np.random.default_rng(seed).permutation(len(failures))]
    known: dict[Config, bool] = {}
    charged: set[Config] = set()
    state = Progress(len(order))
    queue = iter(order)
    active: list[_Search] = []
    results: list[Fix] = []
    spent = False  # a failure was not reached: later ones are not taken (the reached stay a prefix)
    while True:
        while len(active) < concurrent and not spent:
            failure = next(queue, None)
            if failure is None:
                break
            search = _Search(failure, axes(failure.scene), resolution, first_step)
            search.start()
            active.append(search)
            state.started += 1
        if not active:
            break
        asked: list[tuple[_Search, _Ray, float, Config]] = []
        finished: list[tuple[_Search, bool]] = []
        before = len(results)
        for search in active:
            wanted = search.requests()
            if not wanted:
                finished.append((search, True))
                continue
            new = {c for _, _, c in wanted if c not in known and c not in charged and not free(c)}
            if budget is not None and len(charged) + len(new) > budget:
                finished.append((search, False))
                continue
            charged |= new
            asked += [(search, ray, t, c) for ray, t, c in wanted]
        for search, complete in finished:
            active.remove(search)
            if not complete and search.probes == 0:  # not reached: the budget was spent before it
                state.started -= 1
                spent = True
                continue
            results.append(search.result(complete))
            state.finished += 1
            state.found += results[-1].fix is not None
        todo = list(dict.fromkeys(c for *_, c in asked if c not in known))
        if todo:
            verdicts = oracle(todo)
            if len(verdicts) != len(todo):
                raise ValueError(f"the oracle answered {len(verdicts)} of {len(todo)} configurations")
            known.update(zip(todo, (bool(v) for v in verdicts)))
            state.probes += len(todo)
        for search, ray, t, config in asked:
            search.probes += 1
            search.answer(ray, t, config, known[config])
        if not asked and len(results) == before:
            continue  # only failures the budget no longer reaches were looked at: nothing to tell
        state.charged = len(charged)
        state.rounds += 1
        if on_round is not None:
            on_round(state)
    rank = {failure: i for i, failure in enumerate(order)}
    return sorted(results, key=lambda fix: rank[fix.failure])
