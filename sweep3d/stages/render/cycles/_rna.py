"""Assign Blender properties only when their value changes.

Every RNA assignment tags the data as updated, even with an equal value, and with persistent
render data some updates are expensive (a world change rebuilds the importance map, a
visibility change re-syncs geometry). Blender stores floats as float32, so equality is
checked with a float32-sized tolerance.
"""

from __future__ import annotations

import math
from typing import Any


def same(a: Any, b: Any) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        return math.isclose(float(a), float(b), rel_tol=1e-6, abs_tol=1e-7)
    if hasattr(a, "__len__") and hasattr(b, "__len__") and not isinstance(a, str):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return a == b


def assign(target: Any, name: str, value: Any) -> None:
    """``setattr(target, name, value)`` unless the property already holds that value."""
    if not same(getattr(target, name), value):
        setattr(target, name, value)
