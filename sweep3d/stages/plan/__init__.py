"""Plan: expand a spec into jobs, each with the cache keys of the stages it needs."""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.stages.plan.design import SceneRows, check_output, design_order, rows_by_scene, write_design
    from sweep3d.stages.plan.keys_memo import source_digest
    from sweep3d.stages.plan.planner import History, count_jobs, make_plan
    from sweep3d.stages.plan.policies import POLICIES, GridPolicy, Listed, Outcome, Policy, PolicyParams, TablePolicy
    from sweep3d.stages.plan.step_fit import fit_step

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
