"""Plan: expand a spec into jobs, each with the cache keys of the stages it needs."""

from __future__ import annotations

__all__ = ["POLICIES", "History", "Job", "Outcome", "Plan", "Policy", "PolicyParams", "count_jobs",
           "make_plan"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.lazy import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.stages.jobs import Job, Plan
    from sweep3d.stages.plan.planner import History, count_jobs, make_plan
    from sweep3d.stages.plan.policies import POLICIES, Outcome, Policy, PolicyParams

__getattr__, __dir__ = _exports(__name__, {
    'History': ('sweep3d.stages.plan.planner', 'History'),
    'Job': ('sweep3d.stages.jobs', 'Job'),
    'Outcome': ('sweep3d.stages.plan.policies', 'Outcome'),
    'POLICIES': ('sweep3d.stages.plan.policies', 'POLICIES'),
    'Plan': ('sweep3d.stages.jobs', 'Plan'),
    'Policy': ('sweep3d.stages.plan.policies', 'Policy'),
    'PolicyParams': ('sweep3d.stages.plan.policies', 'PolicyParams'),
    'count_jobs': ('sweep3d.stages.plan.planner', 'count_jobs'),
    'make_plan': ('sweep3d.stages.plan.planner', 'make_plan'),
})
