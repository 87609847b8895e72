"""The runner, the one place that wires stages (every computation hands it plans: ``Runner``,
``running``), one run of a spec over it (the pipeline), the plan's status before it runs, and the
built-in catalogue of every stage's plug-ins."""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used. From outside, import through here.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.runner.builtins import builtin_catalogue
    from sweep3d.runner.pipeline import (
        RunResult,
        jobs_table,
        plan_spec,
        plans_as_run,
        remove_leftovers,
        run,
        write_jobs,
        write_plan_images,
        write_unstored_images,
    )
    from sweep3d.runner.runner import STANDARD, Runner, running, session
    from sweep3d.runner.status import PlanStatus, plan_status

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
