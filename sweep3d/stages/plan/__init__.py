"""Plan: expand a spec into jobs, each with the cache keys of the stages it needs."""

from sweep3d.stages.plan.jobs import Job, Plan, make_plan
from sweep3d.stages.plan.policies import POLICIES, Policy, PolicyParams

__all__ = ["POLICIES", "Job", "Plan", "Policy", "PolicyParams", "make_plan"]
