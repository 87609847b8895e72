"""Plan: expand a spec into jobs, each with the cache keys of the stages it needs."""

from sweep3d.stages.jobs import Job, Plan
from sweep3d.stages.plan.planner import History, count_jobs, make_plan
from sweep3d.stages.plan.policies import POLICIES, Outcome, Policy, PolicyParams

__all__ = ["POLICIES", "History", "Job", "Outcome", "Plan", "Policy", "PolicyParams", "count_jobs",
           "make_plan"]
