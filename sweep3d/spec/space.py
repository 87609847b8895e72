"""The search space of one (object, environment) scene, and the map from policy points to values.

Policies never see controls: they emit points made of unit-cube coordinates (one per
continuous dimension) and choice indices (one per discrete dimension). :class:`SearchSpace`
turns such a point into physical control values, so policies are testable on their own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Iterable, Sequence

import numpy as np

from sweep3d.spec.params import Choice, Fixed, Range

if TYPE_CHECKING:
    from sweep3d.spec.loader import ControlInstance


@dataclass(frozen=True)
class Dim:
    control_id: str
    param: str
    space: Range | Choice
    period: float | None = None  # for periodic parameters (angles)

    @property
    def wraps(self) -> bool:
        """True when the range spans a whole period, so its two ends are one configuration."""
        return (self.period is not None and isinstance(self.space, Range)
                and self.space.high - self.space.low >= self.period)

    @property
    def column(self) -> str:
        return f"{self.control_id}_{self.param}"


@dataclass(frozen=True)
class SpaceShape:
    """What a policy knows of a space: how many continuous dims and the size of each discrete one.

    ``wraps`` marks continuous dims whose range covers a whole period (an angle over 360°), where
    unit coordinates 0 and 1 are the same configuration; empty means none wraps.
    """

    n_continuous: int
    choice_sizes: tuple[int, ...]
    wraps: tuple[bool, ...] = ()

    def wrapping(self, dim: int) -> bool:
        return bool(self.wraps) and self.wraps[dim]


@dataclass(frozen=True)
class Point:
    """One point a policy proposes: ``unit`` holds a coordinate in [0, 1] per continuous dimension
    (a range), ``choice`` an option index per discrete one (a list), in :class:`SpaceShape` order."""

    unit: tuple[float, ...]
    choice: tuple[int, ...]


class PointError(ValueError):
    """A policy's points break the contract of :class:`Point`; the message says what was expected."""


def contract(shape: SpaceShape) -> str:
    """What a policy must return for ``shape``, for error messages."""
    sizes = ", ".join(f"0..{size - 1}" for size in shape.choice_sizes)
    floats, lists = shape.n_continuous, len(shape.choice_sizes)
    return (f"return a list of Point(unit, choice) (from sweep3d.plugins) with unit a tuple of {floats} "
            f"float{'s' * (floats != 1)} in [0, 1] and choice a tuple of {lists} option "
            f"ind{'ices' if lists != 1 else 'ex'}" + (f" ({sizes})" if sizes else ""))


def as_points(unit: np.ndarray, choice: np.ndarray) -> list[Point]:
    """Points from a policy's arrays: unit coordinates (n, continuous dims), choices (n, discrete dims)."""
    return [Point(tuple(u), tuple(c)) for u, c in zip(unit.tolist(), choice.tolist())]


def as_arrays(points: Sequence[Point], shape: SpaceShape) -> tuple[np.ndarray, np.ndarray]:
    """The arrays of :func:`as_points` for ``points`` (float64 and int64, one row per point).

    Raises:
        PointError: ``points`` is not a list of :class:`Point` of ``shape``'s sizes, with numbers
            for coordinates and whole numbers for choices (the range of each is checked apart).
    """
    if isinstance(points, (str, bytes, Point)) or not isinstance(points, Iterable):
        raise PointError(f"its points are {_what(points)}, not a list of points; {contract(shape)}")
    points = list(points)
    sizes = (shape.n_continuous, len(shape.choice_sizes))
    for i, p in enumerate(points):
        if not isinstance(p, Point):
            raise PointError(f"its point {i} is {_what(p)}, not a Point; {contract(shape)}")
        for field, size in zip(("unit", "choice"), sizes):
            value = getattr(p, field)
            if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != size:
                got = f"{len(value)} values" if isinstance(value, Sequence) else _what(value)
                raise PointError(f"its point {i} has {got} as {field} where this scene's space needs {size}; "
                                 f"{contract(shape)}")
    try:
        unit = np.array([p.unit for p in points], dtype=np.float64).reshape(len(points), sizes[0])
        choice = np.array([p.choice for p in points], dtype=np.float64).reshape(len(points), sizes[1])
    except (TypeError, ValueError) as exc:
        raise PointError(f"its points hold something that is not a number ({exc}); {contract(shape)}") from None
    whole = np.isfinite(choice) & (choice == np.round(choice))
    if not whole.all():
        i, d = (int(x) for x in np.argwhere(~whole)[0])
        raise PointError(f"its point {i} has choice {points[i].choice[d]!r} at index {d}, not an option index; "
                         f"{contract(shape)}")
    return unit, choice.astype(np.int64)


def _what(value: Any) -> str:
    """``a tuple``, ``None``, ``a str``: what a value is, for error messages."""
    return "None" if value is None else f"a {type(value).__name__} ({value!r:.40})"


@dataclass(frozen=True)
class Column:
    """One parameter's values over a batch of points, unvalidated: for a list, the option each
    point picks (``index``; None when there is one option, a fixed value); for a range, ``numbers``."""

    options: tuple[Any, ...] = ()
    index: np.ndarray | None = None
    numbers: np.ndarray | None = None


class SearchSpace:
    """The dimensions that the controls applying to one scene leave open."""

    def __init__(self, controls: Sequence[ControlInstance]) -> None:
        self.controls = list(controls)
        self.continuous: list[Dim] = []
        self.discrete: list[Dim] = []
        for inst in self.controls:
            for param, space in inst.spaces.items():
                if isinstance(space, Range):
                    self.continuous.append(Dim(inst.id, param, space, inst.control.periodic.get(param)))
                elif isinstance(space, Choice):
                    self.discrete.append(Dim(inst.id, param, space))

    @property
    def shape(self) -> SpaceShape:
        return SpaceShape(len(self.continuous), tuple(len(d.space.options) for d in self.discrete),
                          tuple(d.wraps for d in self.continuous))

    def values(self, point: Point) -> dict[str, dict[str, Any]]:
        """Control id → parameter → physical value, including fixed parameters."""
        if len(point.unit) != len(self.continuous) or len(point.choice) != len(self.discrete):
            raise ValueError("point does not match the space's shape")
        out: dict[str, dict[str, Any]] = {}
        for inst in self.controls:
            out[inst.id] = {p: s.value for p, s in inst.spaces.items() if isinstance(s, Fixed)}
        for dim, u in zip(self.continuous, point.unit):
            out[dim.control_id][dim.param] = dim.space.at(u)
        for dim, index in zip(self.discrete, point.choice):
            out[dim.control_id][dim.param] = dim.space.options[index]
        return out

    def columns(self, unit: np.ndarray, choice: np.ndarray) -> dict[str, dict[str, Column]]:
        """:meth:`values` of many points at once: control id → parameter → :class:`Column`.

        Args:
            unit: (points, continuous dims) unit coordinates; choice: (points, discrete dims) indices.
        """
        if unit.shape[1:] != (len(self.continuous),) or choice.shape[1:] != (len(self.discrete),):
            raise ValueError("points do not match the space's shape")
        out: dict[str, dict[str, Column]] = {}
        for inst in self.controls:
            out[inst.id] = {p: Column((s.value,)) for p, s in inst.spaces.items() if isinstance(s, Fixed)}
        for d, dim in enumerate(self.continuous):
            out[dim.control_id][dim.param] = Column(numbers=dim.space.at_many(unit[:, d]))
        for d, dim in enumerate(self.discrete):
            out[dim.control_id][dim.param] = Column(tuple(dim.space.options), index=choice[:, d])
        return out
