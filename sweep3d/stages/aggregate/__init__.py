"""Aggregate: accuracy overall, per control value, per scene, and the failures, by SQL over the store."""

from sweep3d.stages.aggregate.summary import ControlEffect, Summary, summarise

__all__ = ["ControlEffect", "Summary", "summarise"]
