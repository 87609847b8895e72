"""The search space of one (object, environment) scene, and the map from policy points to values.

Policies never see controls: they emit points made of unit-cube coordinates (one per
continuous dimension) and choice indices (one per discrete dimension). :class:`SearchSpace`
turns such a point into physical control values, so policies are testable on their own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from sweep3d.spec.loader import ControlInstance
from sweep3d.spec.params import Choice, Fixed, Range


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
    unit: tuple[float, ...]
    choice: tuple[int, ...]


def as_points(unit: np.ndarray, choice: np.ndarray) -> list[Point]:
    """Points from a policy's arrays: unit coordinates (n, continuous dims), choices (n, discrete dims)."""
    return [Point(tuple(u), tuple(c)) for u, c in zip(unit.tolist(), choice.tolist())]


def as_arrays(points: Sequence[Point], shape: SpaceShape) -> tuple[np.ndarray, np.ndarray]:
    """The arrays of :func:`as_points` for ``points`` (float64 and int64, one row per point)."""
    unit = np.array([p.unit for p in points], dtype=np.float64).reshape(len(points), shape.n_continuous)
    choice = np.array([p.choice for p in points], dtype=np.int64).reshape(len(points), len(shape.choice_sizes))
    return unit, choice


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
