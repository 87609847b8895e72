"""Aggregate: accuracy overall, per control value, per scene, and the failures, by SQL over the store.

:func:`connect` opens a store with the SQL views and macros behind the report's numbers
(per-level accuracy with Wilson intervals, failure modes, variance explained, …), so
``sweep3d query`` and the report read the same numbers.
"""

from __future__ import annotations

__all__ = [
    "ALPHA", "CONFIRMED", "create_margin_macro", "margin_sql", "pairs_needed", "renders_for", "COUNTERFACTUAL_VIEWS", "ControlEffect", "DEFAULT_RENDERS", "HIDDEN",
    "MACROS", "MARGIN_EDGES", "MEASURES", "OCCLUDED", "OUTCOMES", "OUT_OF_FRAME", "PHOTOS_FOLDER", "PlannedStore",
    "Region", "SCENE_COLUMNS", "SCHEMA", "Scale", "Summary", "UNCONFIRMED", "VERDICTS",
    "VERDICT_SCHEMA", "VIEW", "VIEWS", "Verdict", "arrow", "boundary_phrase", "connect",
    "control_effects", "control_number", "counterfactuals_path", "fragile_sentence", "has_view",
    "identifier", "judge", "literal", "materialise", "named_rules", "nearest_miss_region",
    "no_results", "numeric_scales", "photo_path", "plan_protocol", "region_min_count",
    "register_failure_boundaries", "register_views", "results_connection", "results_roles",
    "results_store", "select_only", "stored_parameters", "stored_summary", "summarise", "tally",
    "verdict_key", "weakest_regions", "wilson_interval"
]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.results.agreement import PHOTOS_FOLDER, VERDICT_SCHEMA, VERDICTS, photo_path, verdict_key
    from sweep3d.results.base_views import plan_protocol, results_roles
    from sweep3d.results.boundaries import (
        VIEW,
        Scale,
        boundary_phrase,
        control_number,
        numeric_scales,
        register_failure_boundaries,
    )
    from sweep3d.results.confirmation import (
        ALPHA,
        CONFIRMED,
        DEFAULT_RENDERS,
        UNCONFIRMED,
        Verdict,
        judge,
        pairs_needed,
        renders_for,
        tally,
    )
    from sweep3d.results.counterfactuals import COUNTERFACTUAL_VIEWS, SCHEMA, counterfactuals_path
    from sweep3d.results.fragile import MARGIN_EDGES, create_margin_macro, fragile_sentence, margin_sql
    from sweep3d.results.measures import MEASURES
    from sweep3d.results.own_jobs import PlannedStore, results_store
    from sweep3d.results.quoting import identifier, literal
    from sweep3d.results.sql import arrow, results_connection, select_only
    from sweep3d.results.summary import (
        ControlEffect,
        Region,
        Summary,
        control_effects,
        named_rules,
        nearest_miss_region,
        region_min_count,
        stored_summary,
        summarise,
        weakest_regions,
    )
    from sweep3d.results.task_views import HIDDEN, OCCLUDED, OUT_OF_FRAME, OUTCOMES
    from sweep3d.results.views import (
        MACROS,
        SCENE_COLUMNS,
        VIEWS,
        connect,
        has_view,
        materialise,
        no_results,
        register_views,
        stored_parameters,
        wilson_interval,
    )

__getattr__, __dir__ = _exports(__name__, {
    "ALPHA": ("sweep3d.results.confirmation", "ALPHA"),
    "CONFIRMED": ("sweep3d.results.confirmation", "CONFIRMED"),
    "pairs_needed": ("sweep3d.results.confirmation", "pairs_needed"),
    "renders_for": ("sweep3d.results.confirmation", "renders_for"),
    "create_margin_macro": ("sweep3d.results.fragile", "create_margin_macro"),
    "margin_sql": ("sweep3d.results.fragile", "margin_sql"),
    "COUNTERFACTUAL_VIEWS": ("sweep3d.results.counterfactuals", "COUNTERFACTUAL_VIEWS"),
    "ControlEffect": ("sweep3d.results.summary", "ControlEffect"),
    "DEFAULT_RENDERS": ("sweep3d.results.confirmation", "DEFAULT_RENDERS"),
    "HIDDEN": ("sweep3d.results.task_views", "HIDDEN"),
    "MACROS": ("sweep3d.results.views", "MACROS"),
    "MARGIN_EDGES": ("sweep3d.results.fragile", "MARGIN_EDGES"),
    "MEASURES": ("sweep3d.results.measures", "MEASURES"),
    "OCCLUDED": ("sweep3d.results.task_views", "OCCLUDED"),
    "OUTCOMES": ("sweep3d.results.task_views", "OUTCOMES"),
    "OUT_OF_FRAME": ("sweep3d.results.task_views", "OUT_OF_FRAME"),
    "PlannedStore": ("sweep3d.results.own_jobs", "PlannedStore"),
    "Region": ("sweep3d.results.summary", "Region"),
    "SCENE_COLUMNS": ("sweep3d.results.views", "SCENE_COLUMNS"),
    "SCHEMA": ("sweep3d.results.counterfactuals", "SCHEMA"),
    "Scale": ("sweep3d.results.boundaries", "Scale"),
    "Summary": ("sweep3d.results.summary", "Summary"),
    "UNCONFIRMED": ("sweep3d.results.confirmation", "UNCONFIRMED"),
    "VERDICTS": ("sweep3d.results.agreement", "VERDICTS"),
    "PHOTOS_FOLDER": ("sweep3d.results.agreement", "PHOTOS_FOLDER"),
    "VERDICT_SCHEMA": ("sweep3d.results.agreement", "VERDICT_SCHEMA"),
    "VIEW": ("sweep3d.results.boundaries", "VIEW"),
    "VIEWS": ("sweep3d.results.views", "VIEWS"),
    "Verdict": ("sweep3d.results.confirmation", "Verdict"),
    "arrow": ("sweep3d.results.sql", "arrow"),
    "boundary_phrase": ("sweep3d.results.boundaries", "boundary_phrase"),
    "connect": ("sweep3d.results.views", "connect"),
    "control_effects": ("sweep3d.results.summary", "control_effects"),
    "control_number": ("sweep3d.results.boundaries", "control_number"),
    "counterfactuals_path": ("sweep3d.results.counterfactuals", "counterfactuals_path"),
    "fragile_sentence": ("sweep3d.results.fragile", "fragile_sentence"),
    "has_view": ("sweep3d.results.views", "has_view"),
    "identifier": ("sweep3d.results.quoting", "identifier"),
    "judge": ("sweep3d.results.confirmation", "judge"),
    "literal": ("sweep3d.results.quoting", "literal"),
    "materialise": ("sweep3d.results.views", "materialise"),
    "named_rules": ("sweep3d.results.summary", "named_rules"),
    "nearest_miss_region": ("sweep3d.results.summary", "nearest_miss_region"),
    "no_results": ("sweep3d.results.views", "no_results"),
    "numeric_scales": ("sweep3d.results.boundaries", "numeric_scales"),
    "photo_path": ("sweep3d.results.agreement", "photo_path"),
    "verdict_key": ("sweep3d.results.agreement", "verdict_key"),
    "plan_protocol": ("sweep3d.results.base_views", "plan_protocol"),
    "region_min_count": ("sweep3d.results.summary", "region_min_count"),
    "register_failure_boundaries": ("sweep3d.results.boundaries", "register_failure_boundaries"),
    "register_views": ("sweep3d.results.views", "register_views"),
    "results_connection": ("sweep3d.results.sql", "results_connection"),
    "results_roles": ("sweep3d.results.base_views", "results_roles"),
    "results_store": ("sweep3d.results.own_jobs", "results_store"),
    "select_only": ("sweep3d.results.sql", "select_only"),
    "stored_parameters": ("sweep3d.results.views", "stored_parameters"),
    "stored_summary": ("sweep3d.results.summary", "stored_summary"),
    "summarise": ("sweep3d.results.summary", "summarise"),
    "tally": ("sweep3d.results.confirmation", "tally"),
    "weakest_regions": ("sweep3d.results.summary", "weakest_regions"),
    "wilson_interval": ("sweep3d.results.views", "wilson_interval"),
})
