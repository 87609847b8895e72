"""One grade per finding from the checks' verdicts: pure, so a simulation can test it.

The checks, in the order they are made (each only where the one before left the finding standing):

1. **Replication** (``confirm``'s sequential twins on fresh renders): confirmed, not replicated
   (the effect bounded below :data:`~sweep3d.results.confirmation.FUTILITY`), inconclusive (the
   budget ended first) or untested (no fresh twin could be drawn).
2. **The second renderer**: the same twins rendered by the other engine, in looks from a few
   pairs up to the replication's (:func:`second_opinion`), each finding judged alone: reproduced
   (McNemar's one-sided test at 5 %, split over the looks), or bounded below the futility size
   (*renderer-sensitive*); anything else leaves the finding *inconclusive*.
3. **Fragility**: the fresh twins judged again with each wrong verdict whose ``|margin|`` is below
   the stability check's fragile threshold counted as right (a change no eye sees could flip it).
   A finding that no longer holds at 5 % is *fragile*.

A finding that passes all three is *solid*.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable, Mapping, Sequence

from sweep3d.results import (
    ALPHA,
    CONFIRMED,
    FRAGILE,
    INCONCLUSIVE_GRADE,
    NOT_REPLICATED,
    NOT_REPLICATED_GRADE,
    RENDERER_SENSITIVE,
    SOLID,
    UNTESTED,
    Verdict,
    judge,
    pairs_to_confirm,
    sequential,
    tally,
)

#: One twin pair's verdicts: (inside correct, outside correct).
Pair = tuple[bool, bool]
#: One twin's result: counted, correct, margin (None without one).
Twin = tuple[bool, bool, "float | None"]


@dataclass(frozen=True)
class Evidence:
    """What the checks found of one finding (None: that check was not made)."""

    replication: Verdict | None = None
    engine: Verdict | None = None  # the second renderer's verdict on the same twins
    engine_name: str = "the second renderer"
    steady: Verdict | None = None  # the replication with fragile wrong verdicts counted as right
    set_aside: int = 0  # wrong verdicts set aside as fragile
    threshold: float | None = None  # the fragile threshold of |margin| used
    untested: str | None = None  # why no check could be made
    candidates: int = 0  # fresh pairs that could be drawn for it (the budget may have given it fewer)


def single(pairs: Iterable[Pair]) -> Verdict:
    """The verdict of one finding's twins judged alone, in one look at :data:`ALPHA`."""
    return judge([tally(pairs)], ALPHA, 1, 1)[0]


def steady_pairs(twins: Iterable[tuple[tuple[bool, float | None], tuple[bool, float | None]]],
                 threshold: float) -> tuple[list[Pair], int]:
    """``twins`` ((correct, margin) inside, outside) with each wrong verdict whose ``|margin|`` is
    below ``threshold`` counted as right; and how many were."""
    out, set_aside = [], 0
    for inside, outside in twins:
        pair = []
        for correct, margin in (inside, outside):
            flip = not correct and margin is not None and abs(margin) < threshold
            set_aside += flip
            pair.append(correct or flip)
        out.append((pair[0], pair[1]))
    return out, set_aside


def second_opinion(findings: int, first: int, cap: int,
                   fetch: Callable[[Mapping[int, int]], Mapping[int, list[Pair]]],
                   caps: Sequence[int] | None = None) -> list[Verdict]:
    """The second renderer's verdicts on the replicated findings' twins, in looks doubling the pairs
    from ``first`` to ``cap`` (``fetch({finding: pairs wanted})`` gives each open finding's first
    pairs, fewer where it has no more; ``caps``: each finding's most pairs, its looks only those
    that add to them). Each finding is judged alone, at :data:`ALPHA` split over its looks
    (Bonferroni): the replication has already controlled the error over the findings,
    so the second renderer asks of one finding only whether it shows it too (a finding without a
    real effect is graded solid with probability at most the replication's ALPHA: the second check,
    on the same twins and so not independent of the first, can only lower it)."""
    return sequential(findings, first, cap, lambda asked: {i: tally(p) for i, p in fetch(asked).items()},
                      together=False, caps=caps)


def evidence_of(replication: Verdict, twins: list[tuple[Twin, Twin]], engine: Verdict | None,
                engine_name: str, threshold: float | None, candidates: int = 0) -> Evidence:
    """The evidence of one finding: its replication's verdict on ``twins`` (each twin's counted,
    correct, margin), the second renderer's verdict on the same twins (None: not rendered), and the
    fragile threshold of ``|margin|`` (None: no stability check)."""
    steady, set_aside = None, 0
    if threshold is not None and twins and all(a[2] is not None and b[2] is not None for a, b in twins):
        pairs, set_aside = steady_pairs((((a[1], a[2]), (b[1], b[2])) for a, b in twins), threshold)
        steady = single(pairs)
    return Evidence(replication, engine, engine_name, steady, set_aside, threshold, candidates=candidates)


def _points(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:+.0f} pts"


def _effect(v: Verdict) -> str:
    """``-46 pts on 28 fresh pairs (-62 pts to -23 pts, Holm p = 0.002)``: the interval at the level
    of the look that decided (1 - 5 % / looks); Holm's p over the findings judged together (one
    finding alone: its own p)."""
    p = f"Holm p = {v.p_holm:.2g}" if v.findings > 1 else f"p = {v.p_value:.2g}"
    return (f"{_points(v.difference)} on {v.pairs} fresh pair{'s' * (v.pairs != 1)} ({_points(v.difference_low)} to "
            f"{_points(v.difference_high)}, {p})")


def grade(e: Evidence) -> tuple[str, str]:
    """The grade of one finding and its evidence in one sentence (see the module)."""
    if e.untested:
        return UNTESTED, e.untested
    r = e.replication
    if r is None:
        return UNTESTED, "the budget gave it no fresh renders"
    if r.pairs == 0 and e.candidates:
        return INCONCLUSIVE_GRADE, ("the budget gave it no fresh pair: its renders went where they were worth more "
                                    "(pairs that cost fewer renders, or effects nearer a decision); "
                                    f"{pairs_to_confirm(r)} pairs at least could confirm it")
    if r.pairs == 0:
        return UNTESTED, "no fresh configuration could be drawn for it"
    if r.status == NOT_REPLICATED:
        return NOT_REPLICATED_GRADE, f"fresh renders bound its effect below {r.futility:.0%}: {_effect(r)}"
    if r.status != CONFIRMED:
        need = pairs_to_confirm(r)
        short = f"; {need} pairs at least could confirm it" if r.pairs < need else ""
        return INCONCLUSIVE_GRADE, f"the budget ended before fresh renders decided: {_effect(r)}{short}"
    replicated = f"replicated: {_effect(r)}"
    g = e.engine
    if g is None:
        return INCONCLUSIVE_GRADE, f"{replicated}; {e.engine_name} was not checked within the budget"
    if g.status == NOT_REPLICATED:
        return RENDERER_SENSITIVE, f"{replicated}; {e.engine_name} bounds it below {g.futility:.0%}: {_effect(g)}"
    if g.status != CONFIRMED:
        return INCONCLUSIVE_GRADE, f"{replicated}; {e.engine_name} did not decide: {_effect(g)}"
    engine = f"{e.engine_name} reproduces it: {_effect(g)}"
    s = e.steady
    if s is None:
        return INCONCLUSIVE_GRADE, f"{replicated}; {engine}; fragility not checked (no margin, or no stability check)"
    if s.status != CONFIRMED:
        return FRAGILE, (f"{replicated}; {engine}; but not with the {e.set_aside} wrong verdicts within "
                         f"{e.threshold:.3g} of a tie set aside: {_effect(s)}")
    return SOLID, (f"{replicated}; {engine}; holds with the {e.set_aside} fragile verdicts set aside "
                   f"({_points(s.difference)})")
