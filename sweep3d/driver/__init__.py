"""The stage protocol (``Stage``, ``Feed``, ``Computed``), the loop that runs stages over a plan,
the jobs they run, the passes a run needs, plug-in code identity, outcomes and progress."""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used. From outside, import through here.
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

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
