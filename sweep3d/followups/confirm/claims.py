"""Findings as claims: a region of one parameter against the rest, as plain data.

A claim says "the model does worse when ``parameter`` is in ``inside`` than when it is in
``outside``", possibly within one object or environment (``scope``). A failure mode
``occluder = half`` is the value against the parameter's other values; a binned range's mode
(``yaw = 80–90``) is the bin against the rest of the spec's range; a boundary ``fails below 12.1``
is the range's part below the boundary against the part above (a list's values on either side).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from sweep3d.results import boundary_key, region_key, rule_key  # the findings' keys, named once
from sweep3d.spec import Choice, Range


@dataclass(frozen=True)
class Side:
    """Values of one parameter: listed ``options`` (values of a list, names of objects), or
    ``intervals`` of a range (closed; a draw avoids the other side's values)."""

    options: tuple[Any, ...] = ()
    intervals: tuple[tuple[float, float], ...] = ()

    def __bool__(self) -> bool:
        return bool(self.options) or any(hi >= lo for lo, hi in self.intervals)


@dataclass(frozen=True)
class Claim:
    """One finding to confirm (see the module). ``key`` names it stably: ``run`` and the report
    look its verdict up by it."""

    key: str
    text: str
    parameter: str  # a results column: object, environment or <control id>_<param>
    inside: Side
    outside: Side
    scope: tuple[tuple[str, str], ...] = ()  # (("object", "mug"),): the twins are drawn in that object only
    #: a rule's box: (column, its interval or value) per control parameter; ``parameter``, ``inside``
    #: and ``outside`` are then unused: inside is the box, outside the rest of the box's parameters' space
    box: tuple[tuple[str, Side], ...] = ()




def value_claim(column: str, label: str, text: str, space: Choice | Range | None, names: Sequence[str] = (),
                level_value: float | None = None, width: float | None = None) -> Claim | None:
    """The claim of the failure mode ``column = label``.

    Args:
        space: the parameter's space in the spec (None for object and environment, whose ``names``
            are the spec's objects or environments).
        level_value: the level's number (a bin's centre) when the parameter is numeric.
        width: the bin's width when the views binned the parameter (None: one value).

    Returns:
        None when the region has no outside to draw from (one value only).
    """
    key = region_key(column, label)
    if space is None:
        inside, outside = Side((label,)), Side(tuple(n for n in names if n != label))
    elif isinstance(space, Choice):
        chosen = [o for o in space.options if _same(o, label, level_value)]
        if not chosen:
            return None
        inside, outside = Side(tuple(chosen)), Side(tuple(o for o in space.options if o not in chosen))
    elif width is not None and level_value is not None:
        lo, hi = max(space.low, level_value - width / 2), min(space.high, level_value + width / 2)
        inside = Side(intervals=((lo, hi),))
        outside = Side(intervals=tuple((a, b) for a, b in ((space.low, lo), (hi, space.high)) if b > a))
    elif level_value is not None:
        value = int(round(level_value)) if space.integer else level_value  # as the plan holds it: the same key
        inside, outside = Side((value,)), Side(intervals=((space.low, space.high),))
    else:
        return None
    if not inside or not outside:
        return None
    return Claim(key, text, column, inside, outside)


def boundary_claim(row: Mapping[str, Any], text: str, space: Choice | Range) -> Claim | None:
    """The claim of a significant boundary: the failing side of the range (or of the list) against
    the other, within the fit's object or environment."""
    at = row["boundary"]
    below = row["fails"] == "below"
    if isinstance(space, Range):
        low_part, high_part = (space.low, at), (at, space.high)
        inside, outside = (low_part, high_part) if below else (high_part, low_part)
        claim_sides = Side(intervals=(inside,)), Side(intervals=(outside,))
    else:
        numbers = [o for o in space.options if isinstance(o, (int, float)) and not isinstance(o, bool)]
        lower = tuple(o for o in numbers if o < at)
        upper = tuple(o for o in numbers if o > at)
        claim_sides = (Side(lower), Side(upper)) if below else (Side(upper), Side(lower))
    if not claim_sides[0] or not claim_sides[1]:
        return None
    scope = () if row["scope"] == "all" else ((row["scope"], row[row["scope"]]),)
    return Claim(boundary_key(row), text, row["parameter"], *claim_sides, scope=scope)



def rule_claim(rule: Mapping[str, Any], spaces: Mapping[str, Choice | Range]) -> Claim | None:
    """The claim of a rule (``rules.rule_dict``): its conditions on control parameters form the box,
    its conditions on the object or environment the scope (confirmed within them). None when no
    condition is on a control parameter the spec varies (a rule of scenes alone is a failure mode)."""
    box, scope = [], []
    for c in rule["conditions"]:
        column = c["column"]
        if column in ("object", "environment"):
            scope.append((column, c["value"]))
            continue
        space = spaces.get(column)
        if space is None:
            return None
        if c["value"] is not None:
            options = tuple(o for o in getattr(space, "options", ()) if _same(o, str(c["value"]), _float(c["value"])))
            if isinstance(space, Range):
                options = (int(round(c["value"])) if space.integer else c["value"],)
            if not options:
                return None
            box.append((column, Side(options)))
        else:
            assert isinstance(space, Range)
            low = space.low if c["low"] is None else c["low"]
            high = space.high if c["high"] is None else c["high"]
            if space.integer:  # the rule's low < x <= high in whole numbers (an exclusive low is not in it)
                low = math.floor(low) + 1 if c["low"] is not None else math.ceil(low)
                high = math.floor(high)
                if low > high:  # no whole number in it
                    return None
            elif not low < high:  # the spec's range no longer reaches the rule's interval: nothing to draw
                return None
            box.append((column, Side(intervals=((low, high),))))
    if not box:
        return None
    return Claim(rule_key(rule["key"]), rule["text"], box[0][0], box[0][1], Side(), tuple(scope), tuple(box))


def _float(value: Any) -> float | None:
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def _same(option: Any, label: str, number: float | None) -> bool:
    """Whether a listed ``option`` is the level labelled ``label`` (text as DuckDB casts it, or its number)."""
    if isinstance(option, (int, float)) and not isinstance(option, bool) and number is not None:
        return float(option) == number
    if isinstance(option, bool):
        return str(option).lower() == label.lower()
    return str(option) == label
