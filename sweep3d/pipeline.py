"""Run a spec through plan → render → postprocess → infer, resumable at any point.

The process holding the store's lock is its single writer. Each stage computes only the keys
the store lacks, and flushes rows every few seconds, so a killed run resumes where it stopped.

Before anything is rendered the model is loaded and tried on a blank image (when anything
needs inferring), so a broken model fails in seconds. A stage that finds a damaged blob
upstream discards it; the run then repeats the stages (a few passes at most) to recompute it.
The experiment's jobs table is written once its stages have run, so a run that stops on a
user error leaves the store's tables as they were.
"""

from __future__ import annotations

import functools
import time
import uuid
from dataclasses import dataclass, field

from rich.console import Console

from sweep3d.cache.store import TABLES, Store, utc_now
from sweep3d.errors import SpecError, UserError
from sweep3d.progress import RunProgress
from sweep3d.spec.framing import Framing, resolve_framing
from sweep3d.spec.loader import LoadedSpec
from sweep3d.stages.infer import infer_stage
from sweep3d.stages.infer.stage import ReadyModel, pending_predictions, prepare_model
from sweep3d.stages.outcome import StageOutcome
from sweep3d.stages.plan import Plan, make_plan
from sweep3d.stages.plan.jobs import History
from sweep3d.stages.plan.policies import Outcome
from sweep3d.stages.postprocess import postprocess_stage
from sweep3d.stages.render import render_stage
from sweep3d.stages.render.stage import LOCAL, Executor


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


def outcomes_by_scene(plan: Plan, store: Store) -> History:
    """What the model did on each job of ``plan``, per scene, for adaptive policies.

    A job with no valid prediction (its render failed, or the model gave NaN) counts as not
    failed with zero loss, so the search moves on instead of waiting for it.
    """
    con = store.connect()
    rows: dict[str, tuple] = {}
    if store.segments("predictions"):
        keys = list({j.pred_key for j in plan.jobs})
        rows = {r[0]: r[1:] for r in con.execute(
            "SELECT pred_key, valid, correct, loss FROM predictions WHERE pred_key IN (SELECT unnest(?))", [keys]
        ).fetchall()}
    history: History = {}
    for job in plan.jobs + plan.out_of_frame:
        valid, correct, loss = rows.get(job.pred_key, (False, None, None))
        outcome = Outcome(failed=bool(valid and not correct), loss=float(loss) if valid else 0.0)
        history.setdefault(job.scene, {})[job.point] = outcome
    return history


def _merge(before: list[StageOutcome], now: list[StageOutcome]) -> list[StageOutcome]:
    """Add up a stage's outcomes over the passes of one run (adaptive rounds, repair passes).

    Keys cached from an earlier pass of the same run count as computed, not cached. Each pass
    covers the whole plan so far and retries what failed, so failures are the last pass's.
    """
    if not before:
        return now
    merged = []
    for old, new in zip(before, now):
        merged.append(StageOutcome(
            old.stage, total=new.total, cached=old.cached, computed=old.computed + new.computed,
            failed=new.failed, skipped=new.skipped, seconds=old.seconds + new.seconds, errors=new.errors))
    return merged


def write_jobs(plan: Plan, store: Store) -> None:
    """Record the plan as the experiment's jobs table (what ``results`` joins against)."""
    import pyarrow as pa

    store.write_table_file(store.jobs_path(plan.spec.name), pa.Table.from_pylist(plan.rows()))


AUTO_COMPACT_SEGMENTS = 64  # a run ends by merging a table's segments beyond this many
REPAIR_PASSES = 3  # extra passes over the stages when a damaged blob was found (render → post → infer)


def run_stages(plan: Plan, store: Store, progress: RunProgress, model: ReadyModel | None = None,
               executor: Executor = LOCAL) -> list[StageOutcome]:
    """Render, postprocess and infer ``plan``; again while a stage discarded a damaged blob."""
    outcomes: list[StageOutcome] = []
    for _ in range(1 + REPAIR_PASSES):
        discarded = store.discarded
        stages = (functools.partial(render_stage, executor=executor), postprocess_stage,
                  functools.partial(infer_stage, model=model, on_ray=executor.kind == "ray"))
        outcomes = _merge(outcomes, [stage(plan, store, progress) for stage in stages])
        if store.discarded == discarded:
            break
    return outcomes


def _model_digest(spec: LoadedSpec, framing: Framing) -> str:
    """The model's digest for this framing (loads a user's factory), its errors naming ``model.name``."""
    from sweep3d.stages.infer.models import model_digest

    try:
        return model_digest(spec.spec.model.name, framing.model)
    except SpecError:
        raise
    except UserError as exc:
        raise SpecError(str(spec.path), "model.name", str(exc)) from None


def _writable(spec: LoadedSpec, store: Store) -> None:
    try:
        store.ensure_writable()
    except UserError as exc:
        raise SpecError(str(spec.path), "experiment.store", str(exc)) from None


def run(spec: LoadedSpec, console: Console | None = None, wait: float = 0.0, executor: Executor = LOCAL) -> RunResult:
    """Run every stage of ``spec`` and return what each did (renders on ``executor``)."""
    store = Store(spec.store)
    _writable(spec, store)
    owns_ray = False
    if executor.kind == "ray":
        from sweep3d.stages.render.ray_pool import connect

        owns_ray = connect(executor.address)
    try:
        return _run_locked(spec, store, console, wait, executor)
    finally:
        if owns_ray:
            import ray

            ray.shutdown()


def _run_locked(spec: LoadedSpec, store: Store, console: Console | None, wait: float, executor: Executor) -> RunResult:
    with store.lock(wait):
        started = time.perf_counter()  # time spent waiting for the lock is not the run's
        started_at = utc_now()
        for table in TABLES:
            store.sweep_superseded(table)  # segments an earlier compaction merged, past their grace
        framing = resolve_framing(spec)
        result = RunResult(uuid.uuid4().hex[:12], make_plan(spec, _model_digest(spec, framing), framing=framing))
        model = prepare_model(result.plan, store) if pending_predictions(result.plan, store) else None
        with RunProgress(console) as progress:
            history: History = {}
            while True:  # one pass for fixed policies; one per round for adaptive ones
                plan = make_plan(spec, result.plan.model_digest, history, framing) if history else result.plan
                try:
                    outcomes = run_stages(plan, store, progress, model, executor)
                except KeyboardInterrupt:
                    write_jobs(plan, store)  # what finished is stored: let query and report show it
                    raise
                write_jobs(plan, store)
                result.outcomes = _merge(result.outcomes, outcomes)
                grown = len(plan.jobs) > len(result.plan.jobs) or not history
                result.plan = plan
                if not spec.policy.adaptive or not grown:
                    break
                history = outcomes_by_scene(plan, store)
        result.seconds = time.perf_counter() - started
        store.append("runs", [{
            "run_id": result.run_id, "experiment": spec.name, "spec_path": str(spec.path),
            "spec": spec.path.read_text(encoding="utf-8"), "jobs": len(plan.jobs),
            "started_at": started_at, "created_at": utc_now(), "seconds": result.seconds,
            **{f"{o.stage}_{k}": v for o in result.outcomes for k, v in o.as_row().items() if k != "stage"},
        }])
        compact_crowded_tables(store)
    return result


def compact_crowded_tables(store: Store, limit: int = AUTO_COMPACT_SEGMENTS) -> list[str]:
    """Merge the segments of tables that have more than ``limit`` (call it holding the lock).

    Every run adds a few segments per table; readers bind each file, so a store grown over
    hundreds of runs would take seconds to open. Returns the tables merged.
    """
    from sweep3d.cache.maintenance import compact_table

    crowded = [t for t in TABLES if len(store.readable_segments(t)) > limit]
    for table in crowded:
        compact_table(store, table)
    return crowded
