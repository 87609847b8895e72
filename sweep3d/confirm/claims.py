"""Findings as claims: a region of one parameter against the rest, as plain data.

A claim says "the model does worse when ``parameter`` is in ``inside`` than when it is in
``outside``", possibly within one object or environment (``scope``). A failure mode
``occluder = half`` is the value against the parameter's other values; a binned range's mode
(``yaw = 80–90``) is the bin against the rest of the spec's range; a boundary ``fails below 12.1``
is the range's part below the boundary against the part above (a list's values on either side).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from sweep3d.spec.params import Choice, Range


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
    scope: tuple[str, str] | None = None  # ("object", "mug"): the twins are drawn in that object only


def region_key(column: str, label: str) -> str:
    """The key of the failure mode ``column = label``."""
    return f"value {column} = {label}"


def boundary_key(row: Mapping[str, Any]) -> str:
    """The key of a significant boundary (a ``failure_boundaries`` row): its parameter, group, side
    and place (to 6 digits: a boundary that moved is another claim)."""
    who = "" if row["scope"] == "all" else f" {row['scope']} {row[row['scope']]}"
    return f"boundary {row['parameter']}{who} fails {row['fails']} {row['boundary']:.6g}"


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
        inside, outside = Side((level_value,)), Side(intervals=((space.low, space.high),))
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
    scope = None if row["scope"] == "all" else (row["scope"], row[row["scope"]])
    return Claim(boundary_key(row), text, row["parameter"], *claim_sides, scope=scope)


def _same(option: Any, label: str, number: float | None) -> bool:
    """Whether a listed ``option`` is the level labelled ``label`` (text as DuckDB casts it, or its number)."""
    if isinstance(option, (int, float)) and not isinstance(option, bool) and number is not None:
        return float(option) == number
    if isinstance(option, bool):
        return str(option).lower() == label.lower()
    return str(option) == label
