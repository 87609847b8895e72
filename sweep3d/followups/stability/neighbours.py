"""A sampled job's scene neighbours: the same scene with one rendered parameter moved by a change a
person would call invisible, both ways (``yaw+1°``, ``yaw-1°``, ``distance+1%``, ...).

Which parameters move, and how far, comes from each control's ``neighbour_steps`` (parameter →
kind) and the spec's ``[stability]`` table (the size of each kind):

``angle``
    degrees added and taken away (the object's and the camera's angles, a light's direction);
``hdri_rotation``
    degrees the environment map turns;
``distance`` / ``closeness``
    the camera's distance times 1 ± the share: a distance itself is multiplied, a value that grows
    as the camera nears (``zoom``, ``fill``) divided;
``light``
    a light's strength times 1 ± the share.

Only parameters the spec varies (a range or a list) move; a fixed one is the same in every job.
Edges: a range is the space the spec sweeps, so a neighbour past its edge is clipped to it, and a
neighbour clipped onto the job's own value is left out (the other direction still checks the
job); a range over a whole turn of a periodic parameter wraps instead. A list is points, not a
range: its neighbours may fall between or beyond them, within the parameter's own limits
(elevation -90..90), clipped there likewise. An integer range's neighbours are rounded.

Not moved, each listed with its reason: a list of names, a parameter whose control declares no
step, and the post-processing controls (the image changes stand for them). Pure: tests move
thousands of values with no spec loaded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from sweep3d.spec import Choice, Range

#: The kinds of step, and which ``[stability]`` setting sizes each.
KINDS = {"angle": "angle", "hdri_rotation": "hdri_rotation", "distance": "distance", "closeness": "distance",
         "light": "light"}
#: The kinds whose size is a share of the value (the others add degrees).
RELATIVE = frozenset({"distance", "closeness", "light"})


@dataclass(frozen=True)
class Move:
    """One parameter the neighbours move: where it is, how far, and within what."""

    control_id: str
    param: str
    kind: str  # a key of KINDS
    size: float  # degrees, or a share for a relative kind
    space: Choice | Range
    limits: tuple[float, float] = (-math.inf, math.inf)  # the parameter's own (its Params' bounds)
    period: float | None = None
    label: str = ""  # what change names call it ("yaw", "distance", "camera.elevation")

    @property
    def column(self) -> str:
        return f"{self.control_id}_{self.param}"


def change_name(move: Move, sign: int) -> str:
    """The change's name in the ``stability`` table: ``yaw+1°``, ``distance-1%``."""
    amount = f"{move.size * 100:g}%" if move.kind in RELATIVE else f"{move.size:g}°"
    return f"{move.label}{'+' if sign > 0 else '-'}{amount}"


def moved(value: float, move: Move, sign: int) -> float:
    """``value`` moved one step in direction ``sign`` (before any edge)."""
    if move.kind in ("angle", "hdri_rotation"):
        return value + sign * move.size
    if move.kind == "closeness":  # grows as the distance shrinks: the distance times 1 ± size
        return value / (1.0 + sign * move.size)
    return value * (1.0 + sign * move.size)


def neighbour_value(value: Any, move: Move, sign: int) -> float | int | None:
    """The neighbour's value of ``move``'s parameter in direction ``sign``; None where the edge
    leaves no neighbour that way (clipped onto ``value``) or the value is not a finite number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    out = moved(float(value), move, sign)
    low, high = move.limits
    space = move.space
    integer = isinstance(space, Range) and space.integer
    if isinstance(space, Range):
        if move.period is not None and space.high - space.low >= move.period:
            out = space.low + math.fmod(out - space.low, move.period) % move.period  # the whole turn wraps
        else:
            low, high = max(low, space.low), min(high, space.high)
    if integer:
        out = float(round(out))
    out = min(max(out, low), high)
    if not math.isfinite(out) or out == float(value):
        return None
    return int(out) if integer or (isinstance(value, int) and out.is_integer() and move.kind not in RELATIVE) \
        else out


def neighbours(values: dict[str, dict[str, Any]], moves: list[Move]) -> list[tuple[str, Move, Any]]:
    """A job's neighbours: (change name, move, value) for each move whose control applies to the job
    (``values``: control id → parameter → value, as ``Job.values``), plus then minus."""
    out = []
    for move in moves:
        have = values.get(move.control_id, {})
        if move.param not in have:
            continue
        for sign in (1, -1):
            value = neighbour_value(have[move.param], move, sign)
            if value is not None:
                out.append((change_name(move, sign), move, value))
    return out


def plan_moves(controls: list[Any], sizes: dict[str, float]) -> tuple[list[Move], dict[str, str]]:
    """The moves of a spec's varied parameters, and the varied parameters not moved (column → why).

    Args:
        controls: the spec's :class:`~sweep3d.spec.ControlInstance` list.
        sizes: each ``[stability]`` setting's value (``angle``, ``distance``, ``light``, ``hdri_rotation``).
    """
    wanted: list[tuple[Any, str, Choice | Range, str]] = []
    skipped: dict[str, str] = {}
    for inst in controls:
        for param, space in inst.spaces.items():
            if not isinstance(space, (Choice, Range)):
                continue  # fixed: the same in every job
            column = f"{inst.id}_{param}"
            kind = type(inst.control).neighbour_steps.get(param)
            if inst.control.stage != "render":
                skipped[column] = "applied to the image after rendering (the image changes stand for it)"
            elif isinstance(space, Choice) and not all(_number(v) for v in space.options):
                skipped[column] = "a list of names (no step lies between them)"
            elif kind is None:
                skipped[column] = f"its control ({inst.control.type_name}) declares no invisible step for it"
            elif kind not in KINDS:
                skipped[column] = f"its control declares the step {kind!r}, not one of {', '.join(KINDS)}"
            else:
                wanted.append((inst, param, space, kind))
    labels = _labels([(inst.id, param, kind) for inst, param, _, kind in wanted])
    moves = [Move(inst.id, param, kind, float(sizes[KINDS[kind]]), space, _limits(inst.control, param),
                  type(inst.control).periodic.get(param), labels[(inst.id, param)])
             for inst, param, space, kind in wanted]
    return moves, skipped


def _labels(moved: list[tuple[str, str, str]]) -> dict[tuple[str, str], str]:
    """What each change is called: the parameter (``distance`` for a closeness), prefixed with its
    control's id where two moved parameters would share a name."""
    short = {(cid, param): ("distance" if kind == "closeness" else param) for cid, param, kind in moved}
    counts: dict[str, int] = {}
    for name in short.values():
        counts[name] = counts.get(name, 0) + 1
    return {k: (name if counts[name] == 1 else f"{k[0]}.{name}") for k, name in short.items()}


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _limits(control: Any, param: str) -> tuple[float, float]:
    """The bounds ``control``'s ``Params`` declare for ``param`` (ge/gt, le/lt), else unbounded."""
    field = type(control).Params.model_fields.get(param)
    low, high = -math.inf, math.inf
    for rule in getattr(field, "metadata", ()) if field is not None else ():
        for name in ("ge", "gt"):
            bound = getattr(rule, name, None)
            if bound is not None:
                low = max(low, float(bound) if name == "ge" else math.nextafter(float(bound), math.inf))
        for name in ("le", "lt"):
            bound = getattr(rule, name, None)
            if bound is not None:
                high = min(high, float(bound) if name == "le" else math.nextafter(float(bound), -math.inf))
    return low, high
