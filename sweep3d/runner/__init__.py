"""The runner, the one place that wires stages (every computation hands it plans: ``Runner``,
``running``), one run of a spec over it (the pipeline), the plan's status before it runs, and the
built-in catalogue of every stage's plug-ins."""

from __future__ import annotations

__all__ = [
    "PlanStatus", "RunResult", "Runner", "STANDARD", "builtin_catalogue", "jobs_table", "plan_spec", "plan_status",
    "plans_as_run", "remove_leftovers", "run", "running", "write_plan_images", "write_unstored_images"
]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles; from outside the package, import through here.
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
        write_plan_images,
        write_unstored_images,
    )
    from sweep3d.runner.runner import STANDARD, Runner, running
    from sweep3d.runner.status import PlanStatus, plan_status

__getattr__, __dir__ = _exports(__name__, {
    "PlanStatus": ("sweep3d.runner.status", "PlanStatus"),
    "RunResult": ("sweep3d.runner.pipeline", "RunResult"),
    "Runner": ("sweep3d.runner.runner", "Runner"),
    "STANDARD": ("sweep3d.runner.runner", "STANDARD"),
    "builtin_catalogue": ("sweep3d.runner.builtins", "builtin_catalogue"),
    "jobs_table": ("sweep3d.runner.pipeline", "jobs_table"),
    "plan_spec": ("sweep3d.runner.pipeline", "plan_spec"),
    "plan_status": ("sweep3d.runner.status", "plan_status"),
    "plans_as_run": ("sweep3d.runner.pipeline", "plans_as_run"),
    "remove_leftovers": ("sweep3d.runner.pipeline", "remove_leftovers"),
    "run": ("sweep3d.runner.pipeline", "run"),
    "running": ("sweep3d.runner.runner", "running"),
    "write_plan_images": ("sweep3d.runner.pipeline", "write_plan_images"),
    "write_unstored_images": ("sweep3d.runner.pipeline", "write_unstored_images"),
})
