"""Which seed each scene's points come from: per scene, or shared across scenes for a paired design.

Unpaired (the default), a scene draws from ``(experiment seed, object, environment)``, so every
scene gets points of its own. Paired (``[policy] paired = true``) the environment leaves the seed:
every environment of an object gets the same points, so "background A against B" compares the
same poses. ``paired = "all"`` takes the object out too.

A policy that draws each dimension independently (``Policy.separable``: random) draws each
control from a stream of its own, seeded by the control's id, so a control shared by two scenes
pairs even when one of them has an extra control (``environments = [...]``). Any other policy
draws its points jointly (Sobol's coverage is a property of all its dimensions together), so its
seed names every control of the scene: scenes with the same controls pair, others do not.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from sweep3d.cache import digest
from sweep3d.spec import Point, SearchSpace
from sweep3d.stages.plan.checked import policy_arrays
from sweep3d.stages.plan.policies import Outcome, Policy


def scene_seed(seed: int, object_name: str, environment: str) -> int:
    """The unpaired seed of one scene (what every plan before paired designs used)."""
    return _seed([seed, object_name, environment])


def paired_seed(seed: int, object_name: str | None, control_ids: list[str]) -> int:
    """The seed of a paired stream: the experiment's seed, the object (None: shared by every
    object) and the ids of the controls it draws, never the environment."""
    return _seed({"paired": [seed, object_name, control_ids]})


def scene_points(policy: Policy, paired: bool | str, space: SearchSpace, seed: int, object_name: str,
                 environment: str, history: Mapping[Point, Outcome], name: str = "") -> tuple[np.ndarray, np.ndarray]:
    """The policy's points for one scene as arrays (unit coordinates, choices), from the seed
    ``paired`` calls for (see the module's docstring), checked (errors call the policy ``name``)."""
    name = name or type(policy).__name__
    if not paired:
        return policy_arrays(policy, name, space, scene_seed(seed, object_name, environment), history)
    owner = None if paired == "all" else object_name
    if not policy.separable or not space.controls:
        return policy_arrays(policy, name, space, paired_seed(seed, owner, [c.id for c in space.controls]), history)
    parts = [policy_arrays(policy, name, SearchSpace([c]), paired_seed(seed, owner, [c.id]), history)
             for c in space.controls]
    return np.concatenate([u for u, _ in parts], axis=1), np.concatenate([c for _, c in parts], axis=1)


def _seed(parts: Any) -> int:
    return int(digest(parts)[:15], 16)
