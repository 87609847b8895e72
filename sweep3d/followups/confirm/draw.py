"""Fresh twin configurations for a claim: inside and outside its region, matched on the rest.

Each pair shares its object, environment and the value of every parameter but the claim's; the
claim's parameter is drawn inside the region for one twin and outside it for the other. Every
value is drawn at random (seeded) from the spec's own space: a range uniformly (a log range
uniformly in its log, an integer range over its whole numbers), a list uniformly over its
values, the region's side uniformly over its part. For an object or environment claim the twins
differ in their scene; a control that applies in one of the two scenes only has its value there.

Pure: the space is plain data (:func:`space_of` reads it from a spec), so tests draw thousands of
pairs with a synthetic oracle and no rendering.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from sweep3d.followups.confirm.claims import Claim, Side
from sweep3d.spec import Choice, Range

#: A configuration: ``object``, ``environment`` and each applying parameter's column → value.
Row = dict[str, Any]


@dataclass(frozen=True)
class Parameter:
    """One parameter the spec varies, with the scenes its control applies in."""

    column: str
    control_id: str
    param: str
    space: Choice | Range
    scenes: frozenset[tuple[str, str]]


@dataclass(frozen=True)
class Space:
    """What a fresh configuration is drawn from."""

    objects: tuple[str, ...]
    environments: tuple[str, ...]
    parameters: tuple[Parameter, ...]

    def parameter(self, column: str) -> Parameter | None:
        return next((p for p in self.parameters if p.column == column), None)


def space_of(loaded: Any) -> Space:
    """The :class:`Space` of a loaded spec (ranges and lists of its controls; fixed values are the
    controls' own and are left out)."""
    objects = tuple(o.name for o in loaded.objects)
    environments = tuple(e.name for e in loaded.environments)
    parameters = []
    for inst in loaded.controls:
        scenes = frozenset((o, e) for o in objects for e in environments if inst.applies_to(o, e))
        for param, space in inst.spaces.items():
            if isinstance(space, (Choice, Range)):
                parameters.append(Parameter(f"{inst.id}_{param}", inst.id, param, space, scenes))
    return Space(objects, environments, tuple(parameters))


def claim_seed(seed: int, claim: Claim) -> list[int]:
    """The seed of a claim's own draws (its scenes' order, the values its base does not give): the
    confirmation's seed and the claim's key, so each claim's pairs do not depend on which other
    claims are confirmed with it."""
    return [seed, _digest(claim.key)]


def base_row(space: Space, seed: int, scene: tuple[str, str], index: int) -> Row:
    """The ``index``-th base of ``scene``: every parameter drawn from its whole space, from a seed of
    the scene and the index alone. Every claim's ``index``-th pair in a scene starts from it, so
    claims whose twins fall in the same scene share their renders (a blur claim's pair and a
    blur boundary's are one render; an elevation claim's differs from it in one twin only)."""
    rng = np.random.default_rng([seed, _digest(scene[0] + "\0" + scene[1]), index])
    return {p.column: _value(rng, p.space) for p in space.parameters}


def draw_pairs(space: Space, claim: Claim, count: int, seed: int) -> list[tuple[Row, Row]]:
    """``count`` twin pairs (inside, outside) for ``claim``; fewer (none) when no scene has the
    claim's parameter within its scope.

    The pairs go round the claim's scenes in an order of its own, the ``k``-th round taking each
    scene's ``k``-th base (:func:`base_row`). A twin keeps the base's value of the claim's
    parameter when that value is on the twin's side and draws one on that side otherwise: each
    twin's value is still uniform over its side and the pairs are independent (no two share a
    base), while most twins are a base that other claims render too."""
    rng = np.random.default_rng(claim_seed(seed, claim))
    scenes = _scenes(space, claim)
    if not scenes:
        return []
    order = [scenes[i] for i in rng.permutation(len(scenes))]
    target = space.parameter(claim.parameter)
    pairs = []
    for j in range(count):
        obj, env = order[j % len(order)]
        if claim.parameter in ("object", "environment"):
            a, b = _pick(rng, claim.inside), _pick(rng, claim.outside)
            inside_scene = (a, env) if claim.parameter == "object" else (obj, a)
            outside_scene = (b, env) if claim.parameter == "object" else (obj, b)
            base = base_row(space, seed, inside_scene, j // len(order))
            pairs.append((_row(space, inside_scene, base), _row(space, outside_scene, base)))
            continue
        scene = (obj, env)
        base = base_row(space, seed, scene, j // len(order))
        if claim.box:
            inside = {column: _on_side(rng, space.parameter(column).space, side, None, base[column])
                      for column, side in claim.box}
            outside = _box_outside(rng, space, claim, base)
            pairs.append((_row(space, scene, {**base, **inside}), _row(space, scene, {**base, **outside})))
            continue
        value = base[claim.parameter]
        inside = _row(space, scene, {**base, claim.parameter: _on_side(rng, target.space, claim.inside, None, value)})
        outside = _row(space, scene, {**base, claim.parameter: _on_side(rng, target.space, claim.outside,
                                                                         claim.inside, value)})
        pairs.append((inside, outside))
    return pairs


def _digest(text: str) -> int:
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "little")


def _on_side(rng: np.random.Generator, space: Choice | Range, side: Side, avoid: Side | None, base: Any) -> Any:
    """``base`` when it lies on ``side`` (and not on ``avoid``), else a value drawn on ``side``: uniform
    over the side either way, ``base`` being uniform over the whole space."""
    if _within(base, side) and (avoid is None or not _within(base, avoid)):
        return base
    return _side_value(rng, space, side, avoid)


def _scenes(space: Space, claim: Claim) -> list[tuple[str, str]]:
    """The scenes a pair may be drawn in: for an object (environment) claim, the environments
    (objects) it is drawn in, as (object, environment) with the varied one left as given; else the
    scenes where the claim's parameter applies, within its scope."""
    scope = dict(claim.scope)
    if claim.parameter in ("object", "environment"):
        return [(o, e) for o in space.objects[:1] for e in space.environments
                if e == scope.get("environment", e)] if claim.parameter == "object" else \
               [(o, space.environments[0]) for o in space.objects if o == scope.get("object", o)]
    targets = [space.parameter(column) for column in ([c for c, _ in claim.box] or [claim.parameter])]
    if None in targets:
        return []
    return [(o, e) for o in space.objects for e in space.environments if all((o, e) in t.scenes for t in targets)
            and o == scope.get("object", o) and e == scope.get("environment", e)]


def _box_outside(rng: np.random.Generator, space: Space, claim: Claim, base: Row) -> Row:
    """The base's box parameters when they fall outside the box, else drawn from their whole
    spaces until they do (uniformly over the rest of their joint space either way)."""
    if not all(_within(base[column], side) for column, side in claim.box):
        return {column: base[column] for column, _ in claim.box}
    for _ in range(10_000):
        values = {column: _value(rng, space.parameter(column).space) for column, _ in claim.box}
        if not all(_within(values[column], side) for column, side in claim.box):
            return values
    raise ValueError(f"no configuration outside the box of {claim.text!r}")


def _row(space: Space, scene: tuple[str, str], values: Row) -> Row:
    row: Row = {"object": scene[0], "environment": scene[1]}
    row.update({p.column: values[p.column] for p in space.parameters if scene in p.scenes})
    return row


def _pick(rng: np.random.Generator, side: Side) -> Any:
    return side.options[int(rng.integers(len(side.options)))]


def _value(rng: np.random.Generator, space: Choice | Range) -> Any:
    """A value drawn from a whole space."""
    if isinstance(space, Choice):
        return space.options[int(rng.integers(len(space.options)))]
    return _in_interval(rng, space, space.low, space.high)


def _side_value(rng: np.random.Generator, space: Choice | Range, side: Side, avoid: Side | None) -> Any:
    """A value drawn from one side of a claim: its options uniformly, or its intervals uniformly
    by length (in log for a log range, by whole numbers for an integer one), never a value of
    ``avoid`` (the inside, for the outside twin)."""
    if side.options:
        return _pick(rng, side)
    assert isinstance(space, Range)
    pieces = [(lo, hi) for lo, hi in side.intervals if hi >= lo]
    weights = np.array([_measure(space, lo, hi) for lo, hi in pieces], dtype=np.float64)
    weights = weights / weights.sum() if weights.sum() > 0 else np.full(len(pieces), 1 / len(pieces))
    for _ in range(1000):
        lo, hi = pieces[int(rng.choice(len(pieces), p=weights))]
        value = _in_interval(rng, space, lo, hi)
        if avoid is None or not _within(value, avoid):
            return value
    return value  # a side that is all but the avoided values (never in practice: the sides are disjoint)


def _measure(space: Range, lo: float, hi: float) -> float:
    if space.integer:
        return float(max(0, math.floor(hi) - math.ceil(lo) + 1))
    if space.log:
        return math.log(hi) - math.log(lo)
    return hi - lo


def _in_interval(rng: np.random.Generator, space: Range, lo: float, hi: float) -> float | int:
    if space.integer:
        first, last = math.ceil(lo), math.floor(hi)
        return int(rng.integers(first, last + 1)) if last >= first else int(round(lo))
    if space.log:
        return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
    return float(rng.uniform(lo, hi))


def _within(value: Any, side: Side) -> bool:
    """Whether ``value`` lies on ``side``."""
    if side.options:
        return any(value == option for option in side.options)
    return any(lo <= value <= hi for lo, hi in side.intervals)


def scene_order(space: Space, rows: Sequence[Row]) -> list[int]:
    """Each row's index among the jobs a plan of ``rows`` makes: scenes in spec order (objects,
    then environments), rows of a scene in the order given."""
    from sweep3d.stages.plan import design_order

    return design_order(space.objects, space.environments, rows)
