"""Aggregate: accuracy overall, per control value, per scene, and the failures, by SQL over the store.

:func:`connect` opens a store with the SQL views and macros behind the report's numbers
(per-level accuracy with Wilson intervals, failure modes, variance explained, …), so
``sweep3d query`` and the report read the same numbers.
"""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used.
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
        FUTILITY,
        INCONCLUSIVE,
        NOT_REPLICATED,
        OPEN,
        UNCONFIRMED,
        Verdict,
        family_of,
        first_look,
        judge,
        look_z,
        mcnemar_one_sided,
        pairs_needed,
        pairs_to_confirm,
        planned_looks,
        renders_for,
        sequential,
        tally,
    )
    from sweep3d.results.confirmation import wilson as confirmation_wilson
    from sweep3d.results.counterfactuals import (
        COUNTERFACTUAL_VIEWS,
        COUNTERFACTUALS,
        SCHEMA,
        legacy_counterfactuals_path,
    )
    from sweep3d.results.findings import (
        BOUNDARY,
        BOX,
        FAILURE_MODE,
        FINDINGS_TABLE,
        FRAGILE,
        GRADE_VIEWS,
        GRADES,
        IMAGE_SCHEMA,
        IMAGES_TABLE,
        INCONCLUSIVE_GRADE,
        NOT_REPLICATED_GRADE,
        RENDERER_SENSITIVE,
        SOLID,
        UNTESTED,
        Finding,
        boundary_key,
        grade_row,
        image_grade_row,
        latest_listing,
        listed_findings,
        listing_of,
        not_graded,
        record_listing,
        region_key,
        rule_key,
        stored_rows,
    )
    from sweep3d.results.findings import (
        SCHEMA as FINDINGS_SCHEMA,
    )
    from sweep3d.results.fragile import FLIP_RATE, MARGIN_EDGES, create_margin_macro, fragile_sentence, margin_sql
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
        rules_left_out,
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

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
