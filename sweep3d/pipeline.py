"""Run a spec through plan → render → postprocess → infer, resumable at any point.

The process holding the store's lock is its single writer. Each stage computes only the keys
the store lacks, and flushes rows every few seconds, so a killed run resumes where it stopped.
"""

from __future__ import annotations

import time
import uuid
from dataclasses import dataclass, field

from rich.console import Console

from sweep3d.cache.store import Store, utc_now
from sweep3d.progress import RunProgress
from sweep3d.spec.loader import LoadedSpec
from sweep3d.stages.infer import infer_stage
from sweep3d.stages.outcome import StageOutcome
from sweep3d.stages.plan import Plan, make_plan
from sweep3d.stages.postprocess import postprocess_stage
from sweep3d.stages.render import render_stage


@dataclass
class RunResult:
    run_id: str
    plan: Plan
    outcomes: list[StageOutcome] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def failed(self) -> int:
        return sum(o.failed for o in self.outcomes)

    def outcome(self, stage: str) -> StageOutcome:
        return next(o for o in self.outcomes if o.stage == stage)


def write_jobs(plan: Plan, store: Store) -> None:
    """Record the plan as the experiment's jobs table (what ``results`` joins against)."""
    import pyarrow as pa

    store.write_table_file(store.jobs_path(plan.spec.name), pa.Table.from_pylist(plan.rows()))


def run(spec: LoadedSpec, console: Console | None = None, wait: float = 0.0) -> RunResult:
    """Run every stage of ``spec`` and return what each did."""
    store = Store(spec.store)
    started = time.perf_counter()
    started_at = utc_now()
    with store.lock(wait):
        plan = make_plan(spec)
        write_jobs(plan, store)
        result = RunResult(uuid.uuid4().hex[:12], plan)
        with RunProgress(console) as progress:
            for stage in (render_stage, postprocess_stage, infer_stage):
                result.outcomes.append(stage(plan, store, progress))
        result.seconds = time.perf_counter() - started
        store.append("runs", [{
            "run_id": result.run_id, "experiment": spec.name, "spec_path": str(spec.path),
            "spec": spec.path.read_text(encoding="utf-8"), "jobs": len(plan.jobs),
            "started_at": started_at, "created_at": utc_now(), "seconds": result.seconds,
            **{f"{o.stage}_{k}": v for o in result.outcomes for k, v in o.as_row().items() if k != "stage"},
        }])
    return result
