"""One driver for the render, postprocess and infer stages, and for every caller that runs them.

A stage says what its key is, which table and schema its rows go to, what it reads from upstream
and how to compute a batch of jobs; the driver does the rest the same way for each: it finds what
is cached (a row, and its blob where rows own one), drops rows whose blob has gone, discards
cached blobs that fail their digest (so they are recomputed), counts what is waiting on upstream,
shows progress, writes rows in segments every few seconds (so a kill loses little) and discards
damaged upstream blobs. :func:`run_stages` repeats the stages while one of them discarded an
upstream blob, so a damaged blob is recomputed within the same run.
"""

from __future__ import annotations

import time
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any, Iterable, Iterator, Protocol, Sequence

import pyarrow as pa

from sweep3d.cache.blobs import damaged_blobs
from sweep3d.cache.store import Store
from sweep3d.errors import UserError
from sweep3d.progress import RunProgress
from sweep3d.stages.jobs import Job, JobList, Plan
from sweep3d.stages.outcome import StageOutcome

#: Extra passes over the stages when one discarded a damaged blob (render → post → infer).
REPAIR_PASSES = 3
DAMAGED = "are damaged (digest mismatch or undecodable)"


@dataclass
class Computed:
    """What a stage's ``compute`` says about one key.

    Attributes:
        key: the stage's key of the job.
        row: the stage table's row to record (None when the stage recorded it already, e.g. a
            cached render redone only for a pass).
        side: rows for other tables, by table (e.g. ``parts`` for the UV pass).
        error: why the key failed (then nothing is recorded).
        damaged: the upstream blob found damaged, as (table, key): the job is skipped, the blob
            discarded after the stage, and recomputed by the run's next pass.
    """

    key: str
    row: dict[str, Any] | None = None
    side: dict[str, dict[str, Any]] = field(default_factory=dict)
    error: str | None = None
    damaged: tuple[str, str] | None = None


class Stage(Protocol):
    """One stage as the driver sees it.

    Attributes:
        name: shown in progress bars and outcomes ("render", "postprocess", "infer").
        table: the store table its rows go to; ``owns_blobs`` when each row names a blob by its key.
        side_tables: other tables ``compute`` may add rows to, with their schemas.
    """

    name: str
    table: str
    owns_blobs: bool
    side_tables: dict[str, pa.Schema]

    def schema(self, plan: Plan) -> pa.Schema:
        """The columns of :attr:`table`."""

    def key(self, job: Job) -> str | None:
        """The job's key at this stage (a function of the job alone); None when it has nothing to do here."""

    def upstream(self, job: Job) -> tuple[str, str] | None:
        """(table, key) of the stored blob the job reads, or None when it reads none."""

    def incomplete(self, plan: Plan, store: Store, cached: set[str]) -> set[str]:
        """Cached keys to compute again for something of theirs the store lacks (e.g. a pass)."""

    def compute(self, todo: list[Job], plan: Plan, store: Store) -> Iterator[Computed]:
        """Compute ``todo`` (one job per key), yielding one :class:`Computed` per job."""


def unique_jobs(stage: Stage, jobs: Iterable[Job]) -> dict[str, Job]:
    """The first job of each distinct key at ``stage``, in plan order (read-only: a planned plan's
    jobs remember it per key function, as a run asks for it several times per stage)."""
    if isinstance(jobs, JobList):
        return jobs.unique_by(stage.key)
    unique: dict[str, Job] = {}
    for job in jobs:
        key = stage.key(job)
        if key is not None:
            unique.setdefault(key, job)
    return unique


def cached_keys(stage: Stage, plan: Plan, store: Store) -> set[str]:
    """Keys of ``plan`` at ``stage`` that have a row (and a blob, where rows own one)."""
    have = store.keys(stage.table) & set(unique_jobs(stage, plan.jobs))
    return store.existing_blobs(have) if stage.owns_blobs else have


def to_do(stage: Stage, plan: Plan, store: Store, cached: set[str] | None = None) -> list[Job]:
    """One job per key the stage must compute now: missing or incomplete, with its input stored."""
    unique = unique_jobs(stage, plan.jobs)
    cached = cached_keys(stage, plan, store) if cached is None else cached
    needed = (set(unique) - cached) | stage.incomplete(plan, store, cached)
    inputs: dict[str, set[str]] = {}
    todo = []
    for key, job in unique.items():
        if key not in needed:
            continue
        source = stage.upstream(job)
        if source is not None:
            table, upstream_key = source
            if table not in inputs:
                inputs[table] = store.keys(table)
            if upstream_key not in inputs[table] or not store.blob_path(upstream_key).exists():
                continue  # its input failed or was never made: skipped
        todo.append(job)
    return todo


def plan_status(stage: Stage, plan: Plan, store: Store) -> tuple[int, int]:
    """(distinct keys ``plan`` needs at ``stage``, how many the store holds complete)."""
    cached = cached_keys(stage, plan, store)
    return len(unique_jobs(stage, plan.jobs)), len(cached - stage.incomplete(plan, store, cached))


def discard_damaged(stage: Stage, store: Store, cached: set[str]) -> set[str]:
    """The ``cached`` blobs of ``stage`` found damaged, discarded with one warning.

    A stage reading a blob checks its digest, but a blob whose downstream results are all cached
    is never read again: without this a damaged one would stay in the store until ``cache
    verify``. Discarded here, it is recomputed in the same pass (downstream keys are unchanged).
    """
    damaged = damaged_blobs(store, stage.table, cached)
    store.discard(stage.table, damaged, DAMAGED)
    return damaged


def run_stage(stage: Stage, plan: Plan, store: Store, progress: RunProgress) -> StageOutcome:
    """Compute what ``plan`` needs at ``stage`` and the store lacks; record it as it comes."""
    started = time.perf_counter()
    unique = unique_jobs(stage, plan.jobs)
    cached = cached_keys(stage, plan, store)
    if stage.owns_blobs:  # rows whose blob has gone (deleted, quarantined): computed again, one row each
        store.drop_rows(stage.table, (store.keys(stage.table) & set(unique)) - cached)
        cached -= discard_damaged(stage, store, cached)
    todo = to_do(stage, plan, store, cached)
    redo = {stage.key(job) for job in todo} & cached
    outcome = StageOutcome(stage.name, total=len(unique), cached=len(cached - redo))
    outcome.skipped = outcome.total - outcome.cached - len(todo)
    damaged: dict[str, set[str]] = defaultdict(set)
    if todo:
        writers = {stage.table: store.segment_writer(stage.table, stage.schema(plan))}
        writers |= {table: store.segment_writer(table, schema) for table, schema in stage.side_tables.items()}
        with progress.stage(stage.name, len(todo), outcome.cached) as bar:
            try:
                for item in stage.compute(todo, plan, store):
                    if item.error is not None:
                        outcome.failed += 1
                        outcome.errors.append(f"{stage.name} {item.key[:12]}: {item.error}")
                    elif item.damaged is not None:
                        damaged[item.damaged[0]].add(item.damaged[1])
                        outcome.skipped += 1
                    else:
                        outcome.computed += 1
                        if item.row is not None:
                            writers[stage.table].add(item.row)
                        for table, row in item.side.items():
                            writers[table].add(row)
                    bar.advance(failed=item.error is not None)
            finally:
                for writer in writers.values():
                    writer.flush()
    for table, keys in damaged.items():
        store.discard(table, keys, DAMAGED)
        outcome.repaired += len(keys)
    outcome.seconds = time.perf_counter() - started
    return outcome


def run_stages(stages: Sequence[Stage], plan: Plan, store: Store, progress: RunProgress,
               strict: bool = False) -> list[StageOutcome]:
    """Run ``stages`` in order over ``plan``; again while one repaired a damaged blob.

    Args:
        strict: raise on a failed key instead of reporting it (for callers that need every
            result, such as the bench and the contact sheet).

    Raises:
        UserError: with ``strict``, naming the stage, the setting's first error and the count.
    """
    outcomes: list[StageOutcome] = []
    for _ in range(1 + REPAIR_PASSES):
        now = [run_stage(stage, plan, store, progress) for stage in stages]
        outcomes = merge_outcomes(outcomes, now)
        if not any(o.repaired for o in now):
            break
    if strict:
        for outcome in outcomes:
            if outcome.failed:
                raise UserError(f"{outcome.failed} {outcome.stage} jobs failed: {outcome.errors[0].splitlines()[0]}")
    return outcomes


def merge_outcomes(before: list[StageOutcome], now: list[StageOutcome]) -> list[StageOutcome]:
    """Add up each stage's outcomes over the passes of one run (adaptive rounds, repair passes).

    Keys cached from an earlier pass of the same run count as computed, not cached. Each pass
    covers the whole plan so far and retries what failed, so failures are the last pass's.
    """
    if not before:
        return now
    return [StageOutcome(old.stage, total=new.total, cached=old.cached, computed=old.computed + new.computed,
                         failed=new.failed, skipped=new.skipped, seconds=old.seconds + new.seconds,
                         errors=new.errors, repaired=old.repaired + new.repaired)
            for old, new in zip(before, now)]
