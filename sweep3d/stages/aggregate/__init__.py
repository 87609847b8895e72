"""Aggregate: accuracy overall, per control value, per scene, and the failures, by SQL over the store."""

from sweep3d.stages.aggregate.summary import (
    ControlEffect,
    Region,
    Summary,
    summarise,
    weakest_regions,
)

__all__ = ["ControlEffect", "Region", "Summary", "summarise", "weakest_regions"]
