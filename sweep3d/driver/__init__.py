"""The stage protocol (``Stage``, ``Feed``, ``Computed``), the loop that runs stages over a plan,
the jobs they run, the passes a run needs, plug-in code identity, outcomes and progress."""

from __future__ import annotations

__all__ = [
    "Computed", "ControlValues", "Feed", "Found", "Job", "JobList", "PLUGINS_METADATA", "Plan",
    "PlanColumns", "RunProgress", "SPEC_METADATA", "SceneBlock", "StageOutcome", "StageProgress",
    "add_outcomes", "merge_outcomes", "metadata", "needed_passes", "plugin_changes", "recorded_identity",
    "rows_and_cached", "run_stages", "spec_identity", "stage_counts", "truth_passes", "unique_jobs"
]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles; from outside the package, import through here.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.driver.jobs import ControlValues, Job, JobList, Plan, PlanColumns, SceneBlock
    from sweep3d.driver.loop import (
        Found,
        add_outcomes,
        merge_outcomes,
        rows_and_cached,
        run_stages,
        stage_counts,
        unique_jobs,
    )
    from sweep3d.driver.outcome import StageOutcome
    from sweep3d.driver.passes import needed_passes, truth_passes
    from sweep3d.driver.plugin_code import (
        PLUGINS_METADATA,
        SPEC_METADATA,
        metadata,
        plugin_changes,
        recorded_identity,
        spec_identity,
    )
    from sweep3d.driver.progress import RunProgress, StageProgress
    from sweep3d.driver.protocol import Computed, Feed

__getattr__, __dir__ = _exports(__name__, {
    "Computed": ("sweep3d.driver.protocol", "Computed"),
    "ControlValues": ("sweep3d.driver.jobs", "ControlValues"),
    "Feed": ("sweep3d.driver.protocol", "Feed"),
    "Found": ("sweep3d.driver.loop", "Found"),
    "Job": ("sweep3d.driver.jobs", "Job"),
    "JobList": ("sweep3d.driver.jobs", "JobList"),
    "PLUGINS_METADATA": ("sweep3d.driver.plugin_code", "PLUGINS_METADATA"),
    "Plan": ("sweep3d.driver.jobs", "Plan"),
    "PlanColumns": ("sweep3d.driver.jobs", "PlanColumns"),
    "RunProgress": ("sweep3d.driver.progress", "RunProgress"),
    "SPEC_METADATA": ("sweep3d.driver.plugin_code", "SPEC_METADATA"),
    "SceneBlock": ("sweep3d.driver.jobs", "SceneBlock"),
    "StageOutcome": ("sweep3d.driver.outcome", "StageOutcome"),
    "StageProgress": ("sweep3d.driver.progress", "StageProgress"),
    "add_outcomes": ("sweep3d.driver.loop", "add_outcomes"),
    "plugin_changes": ("sweep3d.driver.plugin_code", "plugin_changes"),
    "merge_outcomes": ("sweep3d.driver.loop", "merge_outcomes"),
    "metadata": ("sweep3d.driver.plugin_code", "metadata"),
    "needed_passes": ("sweep3d.driver.passes", "needed_passes"),
    "recorded_identity": ("sweep3d.driver.plugin_code", "recorded_identity"),
    "rows_and_cached": ("sweep3d.driver.loop", "rows_and_cached"),
    "run_stages": ("sweep3d.driver.loop", "run_stages"),
    "spec_identity": ("sweep3d.driver.plugin_code", "spec_identity"),
    "stage_counts": ("sweep3d.driver.loop", "stage_counts"),
    "truth_passes": ("sweep3d.driver.passes", "truth_passes"),
    "unique_jobs": ("sweep3d.driver.loop", "unique_jobs"),
})
