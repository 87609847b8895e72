"""A control parameter in a spec is fixed (a scalar), a discrete set (a list) or a range.

    yaw   = 30                          # fixed
    yaw   = [0, 90, 180]                # discrete: every policy picks among these
    yaw   = { range = [-180, 180] }     # continuous: policies sample inside it
    zoom  = { range = [0.5, 4], log = true }
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Union

import numpy as np

Scalar = Union[bool, int, float, str]


@dataclass(frozen=True)
class Fixed:
    value: Any

    def values(self) -> list[Any]:
        return [self.value]


@dataclass(frozen=True)
class Choice:
    options: tuple[Any, ...]

    def values(self) -> list[Any]:
        return list(self.options)


@dataclass(frozen=True)
class Range:
    low: float
    high: float
    log: bool = False
    integer: bool = False

    def at(self, u: float) -> float | int:
        """The physical value at unit coordinate ``u`` in [0, 1]."""
        u = min(max(float(u), 0.0), 1.0)
        if self.log:
            value = self._log(u)
        else:
            value = self.low + u * (self.high - self.low)
            if not math.isfinite(value):  # high - low overflowed (a range near ±1.8e308)
                value = self.low * (1.0 - u) + self.high * u
        value = min(max(value, self.low), self.high)  # guard rounding at the ends
        if u in (0.0, 1.0):  # the declared bounds exactly (low + (high - low) can round off high)
            value = self.high if u == 1.0 else self.low
        return int(round(value)) if self.integer else value

    def at_many(self, u: np.ndarray) -> np.ndarray:
        """:meth:`at` of each unit coordinate, bit for bit (float64; an object array of ints for
        an integer range). Linear maps use numpy's correctly rounded arithmetic in the same order;
        logarithmic ones call :mod:`math` once per distinct coordinate, as numpy's exp may differ
        from it in the last bit."""
        u = np.asarray(u, dtype=np.float64)
        u = np.where(1.0 < u, 1.0, np.where(0.0 > u, 0.0, u))  # min(max(u, 0), 1), keeping -0.0 as max does
        if self.log:
            distinct, inverse = np.unique(u, return_inverse=True)
            value = np.array([self._log(x) for x in distinct.tolist()], dtype=np.float64)[inverse.reshape(-1)]
        else:
            value = self.low + u * (self.high - self.low)
            if not np.isfinite(value).all():  # high - low overflowed
                value = np.where(np.isfinite(value), value, self.low * (1.0 - u) + self.high * u)
        value = np.where(self.low > value, self.low, value)  # max(value, low)
        value = np.where(self.high < value, self.high, value)  # min(value, high)
        value = np.where(u == 0.0, self.low, np.where(u == 1.0, self.high, value))
        if self.integer:
            return np.array([int(round(v)) for v in value.tolist()], dtype=object)
        return value.astype(np.float64)

    def _log(self, u: float) -> float:
        return math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))

    def values(self) -> list[Any]:
        return [self.low, self.high]


Space = Union[Fixed, Choice, Range]


class ParamSyntaxError(ValueError):
    """The value is not a scalar, a list or a range table; the message says what is expected."""


def parse_space(raw: Any) -> Space:
    """Turn a TOML value into a parameter space (values are checked by the caller)."""
    if isinstance(raw, dict):
        unknown = set(raw) - {"range", "log"}
        if unknown or "range" not in raw:
            raise ParamSyntaxError(
                "expected a scalar, a list, or a table { range = [low, high] } "
                f"(optionally log = true); got keys {sorted(raw)}"
            )
        bounds = raw["range"]
        if not (isinstance(bounds, list) and len(bounds) == 2):
            raise ParamSyntaxError("range must be a list of two numbers [low, high]")
        low, high = bounds
        for bound in bounds:
            if isinstance(bound, bool) or not isinstance(bound, (int, float)):
                raise ParamSyntaxError(f"range bounds must be numbers, got {bound!r}")
            if not math.isfinite(bound):
                raise ParamSyntaxError(f"range bounds must be finite, got {bound!r}")
        if not low < high:
            raise ParamSyntaxError(
                f"empty range [{low}, {high}]: low must be below high (use a scalar to fix a value)"
            )
        log = raw.get("log", False)
        if not isinstance(log, bool):
            raise ParamSyntaxError("log must be true or false")
        if log and low <= 0:
            raise ParamSyntaxError(f"a log range needs low > 0, got {low}")
        return Range(float(low), float(high), log=log)
    if isinstance(raw, list):
        if not raw:
            raise ParamSyntaxError("empty list: give at least one value")
        for item in raw:
            _check_scalar(item)
        seen = list(dict.fromkeys(raw))  # first of each value, by == as `in` would (1 and 1.0 are one), in linear time
        return Choice(tuple(seen)) if len(seen) > 1 else Fixed(seen[0])
    _check_scalar(raw)
    return Fixed(raw)


def _check_scalar(value: Any) -> None:
    if isinstance(value, float) and not math.isfinite(value):
        raise ParamSyntaxError(f"{value!r} is not a finite number")
    if not isinstance(value, (bool, int, float, str)):
        raise ParamSyntaxError(f"expected a number, a string or a boolean, got {value!r}")
