"""Listed values crossed with a policy's draws: every skin on the same poses.

A random or Sobol policy draws a list's value per job, so "4 skins on the same 5 poses" would
need a scene per skin. ``[policy] cross = ["material.skin"]`` takes the list out of what the
policy draws and repeats each draw once per listed value instead; ``{ "material.skin" = 5 }``
does so for the first 5 draws only, the other draws keeping the list's first value. Jobs come
draw by draw, each draw's values in list order (so the first listed value is a draw's first job,
which is the one the paired views match across scenes).

The policy sees the space without the crossed lists, so its draws of the rest do not depend on
how many values a crossed list has; a control with nothing left to draw is left out of it (and of
a jointly seeded policy's seed), so scenes that differ only in crossed controls share their draws.
"""

from __future__ import annotations

import dataclasses
import itertools
from typing import Mapping

import numpy as np

from sweep3d.spec import Choice, ControlInstance, Fixed, SearchSpace


@dataclasses.dataclass(frozen=True)
class Crossing:
    """How one scene's space is crossed: the space the policy draws from, and the crossed lists.

    Attributes:
        drawn: the scene's space with each crossed list fixed at its first value.
        positions: each crossed list's index among the full space's discrete dimensions.
        sizes: how many values each crossed list has.
        firsts: on how many draws each is crossed (None: all).
    """

    drawn: SearchSpace
    positions: tuple[int, ...]
    sizes: tuple[int, ...]
    firsts: tuple[int | None, ...]

    def expand(self, unit: np.ndarray, choice: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The full space's points from the policy's draws: each draw once per crossed combination."""
        if not self.positions:
            return unit, choice
        n = len(unit)
        units, choices = [], []
        for lo, hi, active in self._segments(n):
            combos = np.array(list(itertools.product(*(range(s) if a else (0,) for s, a in zip(self.sizes, active)))),
                              dtype=np.int64).reshape(-1, len(self.sizes))
            draws = np.repeat(np.arange(lo, hi), len(combos))
            full = np.empty((len(draws), choice.shape[1] + len(self.positions)), dtype=np.int64)
            rest = [d for d in range(full.shape[1]) if d not in self.positions]
            full[:, rest] = choice[draws]
            full[:, list(self.positions)] = np.tile(combos, (hi - lo, 1))
            units.append(unit[draws])
            choices.append(full)
        return np.concatenate(units), np.concatenate(choices)

    def count(self, draws: int) -> int:
        """How many jobs ``draws`` draws become."""
        return sum((hi - lo) * int(np.prod([s if a else 1 for s, a in zip(self.sizes, active)]))
                   for lo, hi, active in self._segments(draws))

    def _segments(self, n: int) -> list[tuple[int, int, tuple[bool, ...]]]:
        """Runs of draws ``lo`` .. ``hi - 1`` that cross the same lists (``active``)."""
        cuts = sorted({0, n, *(min(k, n) for k in self.firsts if k is not None)})
        return [(lo, hi, tuple(k is None or lo < k for k in self.firsts)) for lo, hi in zip(cuts, cuts[1:]) if hi > lo]


def crossing(space: SearchSpace, crossed: Mapping[str, int | None]) -> Crossing:
    """The :class:`Crossing` of a scene's ``space`` for ``[policy] cross``'s control parameters
    (``"id.param"`` → first k draws); a crossed parameter that does not apply in the scene is left out."""
    names = [f"{d.control_id}.{d.param}" for d in space.discrete]
    positions = tuple(i for i, name in enumerate(names) if name in crossed)
    if not positions:
        return Crossing(space, (), (), ())
    fixed = {(space.discrete[i].control_id, space.discrete[i].param) for i in positions}
    controls = [_fixed_first(inst, fixed) for inst in space.controls]
    # a control left with nothing to draw once crossed leaves the seed too: the scenes it does not
    # apply in (a skin on white only) then draw jointly seeded policies' (Sobol's) same points
    crossed_ids = {control_id for control_id, _ in fixed}
    controls = [c for c in controls if c.id not in crossed_ids or _draws(c)]
    return Crossing(SearchSpace(controls), positions,
                    tuple(len(space.discrete[i].space.options) for i in positions),
                    tuple(crossed[names[i]] for i in positions))


def _draws(inst: ControlInstance) -> bool:
    """Whether a policy has anything of ``inst`` to draw (a range or a list)."""
    return any(not isinstance(space, Fixed) for space in inst.spaces.values())


def _fixed_first(inst: ControlInstance, fixed: set[tuple[str, str]]) -> ControlInstance:
    """``inst`` with each of its crossed lists fixed at its first value (its id, hence its seed, kept)."""
    spaces = {param: Fixed(space.options[0]) if (inst.id, param) in fixed and isinstance(space, Choice) else space
              for param, space in inst.spaces.items()}
    return dataclasses.replace(inst, spaces=spaces)
