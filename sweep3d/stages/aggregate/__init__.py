"""Aggregate: accuracy overall, per control value, per scene, and the failures, by SQL over the store.

:func:`connect` opens a store with the SQL views and macros behind the report's numbers
(per-level accuracy with Wilson intervals, failure modes, variance explained, …), so
``sweep3d query`` and the report read the same numbers.
"""

from __future__ import annotations

__all__ = ["MACROS", "VIEWS", "ControlEffect", "Region", "Summary", "connect", "control_effects", "has_view",
           "nearest_miss_region",
           "materialise", "no_results", "region_min_count", "register_views", "stored_summary", "summarise", "weakest_regions",
           "wilson_interval"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.lazy import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
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

__getattr__, __dir__ = _exports(__name__, {
    'ControlEffect': ('sweep3d.stages.aggregate.summary', 'ControlEffect'),
    'MACROS': ('sweep3d.stages.aggregate.views', 'MACROS'),
    'Region': ('sweep3d.stages.aggregate.summary', 'Region'),
    'Summary': ('sweep3d.stages.aggregate.summary', 'Summary'),
    'VIEWS': ('sweep3d.stages.aggregate.views', 'VIEWS'),
    'connect': ('sweep3d.stages.aggregate.views', 'connect'),
    'control_effects': ('sweep3d.stages.aggregate.summary', 'control_effects'),
    'has_view': ('sweep3d.stages.aggregate.views', 'has_view'),
    'materialise': ('sweep3d.stages.aggregate.views', 'materialise'),
    'nearest_miss_region': ('sweep3d.stages.aggregate.summary', 'nearest_miss_region'),
    'no_results': ('sweep3d.stages.aggregate.views', 'no_results'),
    'region_min_count': ('sweep3d.stages.aggregate.summary', 'region_min_count'),
    'register_views': ('sweep3d.stages.aggregate.views', 'register_views'),
    'stored_summary': ('sweep3d.stages.aggregate.summary', 'stored_summary'),
    'summarise': ('sweep3d.stages.aggregate.summary', 'summarise'),
    'weakest_regions': ('sweep3d.stages.aggregate.summary', 'weakest_regions'),
    'wilson_interval': ('sweep3d.stages.aggregate.views', 'wilson_interval'),
})
