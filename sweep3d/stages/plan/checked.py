"""A policy's points checked before they become jobs.

A user's policy that raises, returns something other than points, or points outside the space
is one line naming the policy and the contract (see :func:`~sweep3d.spec.space.contract`), not a
traceback from deep in the planner. Built-in policies pass the same checks, which cost a few
array comparisons per scene.
"""

from __future__ import annotations

from typing import Any, Callable, Mapping

import numpy as np

from sweep3d.core import PLUGIN_FAILURES, PluginError, UserError, plugin_failure
from sweep3d.spec import Point, PointError, SearchSpace, SpaceShape, contract
from sweep3d.stages.plan.policies import Outcome, Policy


def policy_arrays(policy: Policy, name: str, space: SearchSpace, seed: int,
                  history: Mapping[Point, Outcome]) -> tuple[np.ndarray, np.ndarray]:
    """``policy.arrays`` for ``space``, checked: unit coordinates finite and in [0, 1], choice
    indices within each list, one row per point in both.

    Raises:
        PluginError: ``policy {name}: ...``, saying what was wrong and what is expected.
    """
    shape = space.shape
    try:
        made = policy.arrays(shape, seed, history)
    except PointError as exc:
        raise PluginError(f"policy {name}: {exc}") from None
    except UserError:
        raise
    except PLUGIN_FAILURES as exc:  # a user's policy failing (or exiting) is the user's to fix
        raise plugin_failure(f"policy {name}", exc, "raised", during="in arrays()") from None
    return _checked(made, shape, space, lambda problem: PluginError(f"policy {name}: {problem}; {contract(shape)}"))


def _checked(made: Any, shape: SpaceShape, space: SearchSpace,
             fail: Callable[[str], PluginError]) -> tuple[np.ndarray, np.ndarray]:
    if not (isinstance(made, tuple) and len(made) == 2):
        raise fail("arrays(shape, seed, history) must return (unit, choice) arrays")
    try:
        unit = np.asarray(made[0], dtype=np.float64)
        choice = np.asarray(made[1])
    except (TypeError, ValueError) as exc:
        raise fail(f"arrays(shape, seed, history) returned values that are not numbers ({exc})") from None
    n = len(unit) if unit.ndim else -1
    if unit.shape != (n, shape.n_continuous) or choice.shape != (n, len(shape.choice_sizes)):
        raise fail(f"arrays(shape, seed, history) returned unit of shape {unit.shape} and choice of shape "
                   f"{choice.shape}; this scene needs ({max(n, 0)}, {shape.n_continuous}) and "
                   f"({max(n, 0)}, {len(shape.choice_sizes)})")
    bad = ~(np.isfinite(unit) & (unit >= 0.0) & (unit <= 1.0))
    if bad.any():
        i, d = (int(x) for x in np.argwhere(bad)[0])
        raise fail(f"its point {i} has unit coordinate {unit[i, d]!r} for {space.continuous[d].column} "
                   "(coordinates are finite numbers in [0, 1])")
    if choice.size and not np.issubdtype(choice.dtype, np.integer):
        raise fail(f"choice indices are whole numbers, got {choice.dtype} values")
    sizes = np.asarray(shape.choice_sizes, dtype=np.int64)
    bad = (choice < 0) | (choice >= sizes)
    if bad.any():
        i, d = (int(x) for x in np.argwhere(bad)[0])
        raise fail(f"its point {i} has choice index {int(choice[i, d])} for {space.discrete[d].column}, which has "
                   f"{shape.choice_sizes[d]} options")
    return unit, choice.astype(np.int64, copy=False)


def policy_count(policy: Policy, name: str, shape: SpaceShape) -> int | None:
    """``policy.count(shape)``, checked: a whole number of points, or None (it cannot say).

    Raises:
        PluginError: ``policy {name}: ...`` when count raises or returns anything else.
    """
    try:
        count = policy.count(shape)
    except UserError:
        raise
    except SystemExit as exc:
        raise plugin_failure(f"policy {name}", exc, during="in count()") from None
    except Exception as exc:  # noqa: BLE001
        raise PluginError(f"policy {name}: count(shape) raised {type(exc).__name__}: {exc}") from None
    if count is None:
        return None
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 0:
        raise PluginError(f"policy {name}: count(shape) returned {count!r}; return how many points points() "
                          "gives for the shape (an int >= 0), or None when it cannot say")
    return int(count)
