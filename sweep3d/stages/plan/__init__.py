"""Plan: expand a spec into jobs, each with the cache keys of the stages it needs."""

from __future__ import annotations

__all__ = [
    "GridPolicy", "History", "Listed", "Outcome", "POLICIES", "Policy", "PolicyParams", "SceneRows",
    "TablePolicy", "check_output", "count_jobs", "fit_step", "make_plan", "write_design"
]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.stages.plan.design import SceneRows, check_output, write_design
    from sweep3d.stages.plan.planner import History, count_jobs, make_plan
    from sweep3d.stages.plan.policies import POLICIES, GridPolicy, Listed, Outcome, Policy, PolicyParams, TablePolicy
    from sweep3d.stages.plan.step_fit import fit_step

__getattr__, __dir__ = _exports(__name__, {
    "GridPolicy": ("sweep3d.stages.plan.policies", "GridPolicy"),
    "History": ("sweep3d.stages.plan.planner", "History"),
    "Listed": ("sweep3d.stages.plan.policies", "Listed"),
    "Outcome": ("sweep3d.stages.plan.policies", "Outcome"),
    "POLICIES": ("sweep3d.stages.plan.policies", "POLICIES"),
    "Policy": ("sweep3d.stages.plan.policies", "Policy"),
    "PolicyParams": ("sweep3d.stages.plan.policies", "PolicyParams"),
    "SceneRows": ("sweep3d.stages.plan.design", "SceneRows"),
    "TablePolicy": ("sweep3d.stages.plan.policies", "TablePolicy"),
    "check_output": ("sweep3d.stages.plan.design", "check_output"),
    "count_jobs": ("sweep3d.stages.plan.planner", "count_jobs"),
    "fit_step": ("sweep3d.stages.plan.step_fit", "fit_step"),
    "make_plan": ("sweep3d.stages.plan.planner", "make_plan"),
    "write_design": ("sweep3d.stages.plan.design", "write_design"),
})
