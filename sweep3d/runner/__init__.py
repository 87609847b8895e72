"""One run of a spec: the pipeline over the stages, the plan's status before it runs, and the
built-in catalogue of every stage's plug-ins."""

from __future__ import annotations

__all__ = [
    "PlanStatus", "RunResult", "builtin_catalogue", "jobs_table", "plan_spec", "plan_status",
    "plans_as_run", "remove_leftovers", "run", "write_plan_images", "write_unstored_images"
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
    from sweep3d.runner.status import PlanStatus, plan_status

__getattr__, __dir__ = _exports(__name__, {
    "PlanStatus": ("sweep3d.runner.status", "PlanStatus"),
    "RunResult": ("sweep3d.runner.pipeline", "RunResult"),
    "builtin_catalogue": ("sweep3d.runner.builtins", "builtin_catalogue"),
    "jobs_table": ("sweep3d.runner.pipeline", "jobs_table"),
    "plan_spec": ("sweep3d.runner.pipeline", "plan_spec"),
    "plan_status": ("sweep3d.runner.status", "plan_status"),
    "plans_as_run": ("sweep3d.runner.pipeline", "plans_as_run"),
    "remove_leftovers": ("sweep3d.runner.pipeline", "remove_leftovers"),
    "run": ("sweep3d.runner.pipeline", "run"),
    "write_plan_images": ("sweep3d.runner.pipeline", "write_plan_images"),
    "write_unstored_images": ("sweep3d.runner.pipeline", "write_unstored_images"),
})
