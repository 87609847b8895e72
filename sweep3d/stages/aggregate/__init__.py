"""Aggregate: accuracy overall, per control value, per scene, and the failures, by SQL over the store.

:func:`connect` opens a store with the SQL views and macros behind the report's numbers
(per-level accuracy with Wilson intervals, failure modes, variance explained, …), so
``sweep3d query`` and the report read the same numbers.
"""

from sweep3d.stages.aggregate.summary import (
    ControlEffect,
    Region,
    Summary,
    control_effects,
    nearest_miss_region,
    region_min_count,
    stored_summary,
    summarise,
    weakest_regions,
)
from sweep3d.stages.aggregate.views import (
    MACROS,
    VIEWS,
    connect,
    has_view,
    materialise,
    no_results,
    register_views,
    wilson_interval,
)

__all__ = ["MACROS", "VIEWS", "ControlEffect", "Region", "Summary", "connect", "control_effects", "has_view",
           "nearest_miss_region",
           "materialise", "no_results", "region_min_count", "register_views", "stored_summary", "summarise", "weakest_regions",
           "wilson_interval"]
