"""Past a fragile fix: the search goes on along the fix's own change, still a pure search.

The nearest fix (:mod:`.search`) is where the model turns right, to within the search's
resolution, so it is often a near tie: right by a margin that the stability check's rule
(:mod:`sweep3d.results.fragile`: ``|margin|`` below the threshold, or the image flipped in the
check) calls a coin flip. Such a fix says little, so for each fragile fix the search probes further
along the same change (the same parameters, the same directions): one search step (``resolution``)
past it, then two, four, … steps, up to the range's end, and keeps the first probe where the model
is right and not fragile. A fix that changes only list options has no further along it, and a
budget may end the probes: such a fix stays the nearest, marked fragile.

A *judge* answers, for a batch of configurations, whether the model is right there, by what margin,
and whether the rule calls that fragile (the driver answers through the stages; tests, with a
function). The same fixes, judge and budget give the same probes in the same order.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable, NamedTuple, Sequence

from sweep3d.followups.explain.search import Axis, Config, Fix, Move, Scene, _Ray, _Search, _t_max


class Judged(NamedTuple):
    """What the model did at one configuration: right, its margin, and whether that is fragile
    (None: no stability check, or no margin)."""

    right: bool
    margin: float | None = None
    fragile: bool | None = None


Judge = Callable[[list[Config]], list[Judged]]


def is_fragile(margin: float | None, threshold: float | None, flipped: bool = False) -> bool | None:
    """The stability check's rule for one verdict: ``|margin|`` below the check's threshold, or its
    image flipped in the check; None without a check (``threshold`` None) or without a margin."""
    if threshold is None:
        return None
    if flipped:
        return True
    return None if margin is None else abs(margin) < threshold


def needs_further(fix: Fix) -> bool:
    """Whether a fix is searched past: one was found and the rule calls it fragile."""
    return fix.fix is not None and fix.fragile is True


def steps_beyond(fix: Fix, axes: Sequence[Axis], resolution: float) -> list[tuple[Config, tuple[Move, ...], float]]:
    """The probes past ``fix`` along its change, nearest first: (configuration, moves, distance) at
    1, 2, 4, … search steps beyond it, the last at the range's end; none for a fix that moves only
    list options (or already at the end)."""
    if fix.fix is None:
        return []
    by_name = {axis.name: axis for axis in axes}
    point = fix.failure.point
    ranges: list[tuple[Axis, int]] = []
    fixed: list[tuple[Axis, int]] = []
    t = 0.0
    for move in fix.moves:
        axis = by_name[move.axis]
        if axis.kind == "range":
            ranges.append((axis, 1 if move.share > 0 else -1))
            t = abs(move.share)  # a ray moves each of its ranges by the same share
        else:
            fixed.append((axis, point.choice[axis.index] + round(move.share * (axis.size - 1))))
    if not ranges:
        return []
    t_max = min(_t_max(point, axis, sign) for axis, sign in ranges)
    base = math.sqrt(sum(m.share ** 2 for m in fix.moves if by_name[m.axis].kind == "list"))
    ray = _Ray(tuple(fixed), tuple(ranges), t_max, base)
    search = _Search(fix.failure, list(axes), resolution, resolution)
    out = []
    steps = 1
    while True:
        u = min(t + steps * resolution, t_max)
        if u <= t + 1e-12:
            break
        out.append((search.config(ray, u), search.moves(ray, u), ray.distance(u)))
        if u >= t_max:
            break
        steps *= 2
    return out


@dataclasses.dataclass
class Further:
    """What the further search did: every fix (a fragile one replaced where a sturdier one was
    found), the distinct configurations it asked, and how many of them were charged."""

    fixes: list[Fix]
    probes: int = 0
    charged: int = 0


def search_further(fixes: Sequence[Fix], axes: Callable[[Scene], list[Axis]], judge: Judge, *,
                   budget: int | None = None, free: Callable[[Config], bool] = lambda c: False,
                   resolution: float = 1 / 64) -> Further:
    """Search past each fragile fix (see the module); the others are returned as they were.

    Args:
        fixes: the search's fixes, their ``fragile`` filled in.
        axes: each scene's open parameters.
        judge: what the model does at each configuration of a batch (asked once per config).
        budget: the most configurations charged (None: no limit); a fix whose next probe does not
            fit stops there (its row's ``complete`` false) and stays as it was, marked fragile.
        free: configurations that cost nothing (evaluated already: the run's jobs, the search's probes).
        resolution: the first step past a fix (a share of the range), then doubled.
    """
    plans = {i: steps_beyond(fix, axes(fix.failure.scene), resolution)
             for i, fix in enumerate(fixes) if needs_further(fix)}
    asked = dict.fromkeys(plans, 0)
    found: dict[int, Judged] = {}
    cut: set[int] = set()
    known: dict[Config, Judged] = {}
    charged: set[Config] = set()
    live = [i for i in plans if plans[i]]
    while live:
        taking = []
        for i in live:
            config = plans[i][asked[i]][0]
            new = {config} - known.keys() - charged if not free(config) else set()
            if budget is not None and len(charged) + len(new) > budget:
                cut.add(i)
                continue
            charged |= new
            taking.append(i)
        todo = list(dict.fromkeys(plans[i][asked[i]][0] for i in taking if plans[i][asked[i]][0] not in known))
        if todo:
            answers = judge(todo)
            if len(answers) != len(todo):
                raise ValueError(f"the judge answered {len(answers)} of {len(todo)} configurations")
            known.update(zip(todo, answers))
        for i in taking:
            judged = known[plans[i][asked[i]][0]]
            asked[i] += 1
            if judged.right and judged.fragile is False:
                found[i] = judged
        live = [i for i in taking if i not in found and asked[i] < len(plans[i])]
    out = []
    for i, fix in enumerate(fixes):
        if i not in plans:
            out.append(fix)
        elif i in found:
            config, moves, distance = plans[i][asked[i] - 1]
            out.append(Fix(fix.failure, config, moves, distance, fix.probes + asked[i], fix.complete,
                           found[i].margin, False, asked[i], fix))
        else:
            out.append(dataclasses.replace(fix, probes=fix.probes + asked[i], further=asked[i],
                                           complete=fix.complete and i not in cut))
    return Further(out, len(known), len(charged))
