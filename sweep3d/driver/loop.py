"""One driver for the render, postprocess and infer stages, and for every caller that runs them.

A stage says what its key is, which table and schema its rows go to, what it reads from upstream
and how to compute its jobs; the driver does the rest the same way for each: it finds what is
cached (a row, and its blob where rows own one), drops rows whose blob has gone, discards cached
blobs that fail their digest (so they are recomputed), counts what is waiting on upstream, shows
progress, writes rows in segments every few seconds (so a kill loses little) and discards damaged
upstream blobs. :func:`run_stages` repeats the stages while one of them discarded an upstream
blob, so a damaged blob is recomputed within the same run.

The stages of a pass overlap: the first runs in the calling thread (the render stage, whose
Blender workers are other processes, so this thread mostly waits on their pipes) and each later
stage in a thread of its own, fed through a :class:`Feed` with the jobs whose input has just been
stored. Only the calling thread records: it counts outcomes, writes every row and hands each
stored key to the stages waiting for it, and it flushes the tables together in stage order, so a
row on disk never lacks the upstream rows it was computed from, whenever the run is killed.
"""

from __future__ import annotations

import queue
import threading
import time
from collections import defaultdict
from contextlib import ExitStack, closing
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping, Sequence

import pyarrow as pa

from sweep3d.cache import (
    BLOB_TABLES,
    DIGEST_COLUMN,
    KEY_COLUMN,
    SegmentWriter,
    Store,
    Verified,
    damaged_blobs,
    remember_verified,
    verified_now,
)
from sweep3d.core import UserError
from sweep3d.driver.jobs import Job, JobList, Plan
from sweep3d.driver.outcome import StageOutcome
from sweep3d.driver.progress import RunProgress, StageProgress
from sweep3d.driver.protocol import Cancelled, Computed, Feed, Stage

#: Extra passes over the stages when one discarded a damaged blob (render → post → infer).
REPAIR_PASSES = 3
DAMAGED = "are damaged (digest mismatch or undecodable)"
#: A pass writes its tables' rows every this many seconds, or when one has this many waiting.
FLUSH_SECONDS = 3.0
FLUSH_ROWS = 64
#: How long a failed or interrupted pass waits for a stage's thread to stop (it ends its item first).
JOIN_SECONDS = 60.0
#: ... and an interrupted one (a thread stuck in a user's plug-in is left behind: it is a daemon).
INTERRUPTED_JOIN_SECONDS = 2.0


def unique_jobs(stage: Stage, jobs: Iterable[Job]) -> Mapping[str, Job]:
    """The first job of each distinct key at ``stage``, in plan order (read-only: a planned plan's
    jobs remember it per key function, as a run asks for it several times per stage, and make
    no job for it where the stage reads its keys from the plan's columns: ``keys_of``)."""
    if isinstance(jobs, JobList):
        return jobs.unique_by(stage.key, _keys_of(stage))
    unique: dict[str, Job] = {}
    for job in jobs:
        key = stage.key(job)
        if key is not None:
            unique.setdefault(key, job)
    return unique


def _keys_of(stage: Stage) -> Callable[[JobList], list[str | None]] | None:
    """The stage's ``keys_of``, where the class that defines it also defines its ``key`` (a
    subclass that changes ``key`` alone gets its keys job by job, never its parent's)."""
    mro = type(stage).__mro__
    owner = next((c for c in mro if "keys_of" in c.__dict__), None)
    if owner is None or owner is not next(c for c in mro if "key" in c.__dict__):
        return None
    return stage.keys_of  # type: ignore[attr-defined]  (optional: see Stage.key)


#: (keys of a plan at a stage that have a row, those of them that are cached): see :func:`rows_and_cached`.
Found = tuple[set[str], set[str]]


def cached_keys(stage: Stage, plan: Plan, store: Store) -> set[str]:
    """Keys of ``plan`` at ``stage`` that have a row (and a blob, where rows own one)."""
    return rows_and_cached(stage, plan, store)[1]


def rows_and_cached(stage: Stage, plan: Plan, store: Store) -> Found:
    """(keys of ``plan`` at ``stage`` that have a row, those of them that are cached: with their
    blob, where rows own one). A stored segment of the plan's keys lacking a column the stage's
    rows always have (``required_columns``, where a stage declares them) is damaged: its rows
    are not counted, and so computed again."""
    unique = unique_jobs(stage, plan.jobs)
    required = getattr(stage, "required_columns", None)
    if required is not None:
        columns, whose = required(plan)
        store.require_columns(stage.table, columns, unique, whose)
    rows = store.key_set(stage.table)
    have = set(rows.intersection(unique))  # in C: 10⁶ keys in a fraction of a second
    return have, (store.existing_blobs(have) if stage.owns_blobs else have)


def to_do(stage: Stage, plan: Plan, store: Store, cached: set[str] | None = None) -> list[Job]:
    """One job per key the stage must compute now: missing or incomplete, with its input stored."""
    return split_to_do(stage, plan, store, cached)[0]


def split_to_do(stage: Stage, plan: Plan, store: Store, cached: set[str] | None = None,
                coming: Mapping[str, set[str]] | None = None) -> tuple[list[Job], dict[tuple[str, str], list[Job]]]:
    """The jobs the stage must compute: (those whose input is stored, those waiting for theirs).

    Args:
        coming: keys that stages upstream will store in this pass, by table; a job whose input
            is coming waits for it even when it is stored (a render made again for its passes:
            the job may read them), and one whose input is neither stored nor coming is skipped
            (its input failed or was never made).
    Returns:
        one job per key: the ready ones in plan order, and the waiting ones by their input's
        (table, key).
    """
    unique = unique_jobs(stage, plan.jobs)
    cached = cached_keys(stage, plan, store) if cached is None else cached
    needed = (set(unique) - cached) | stage.incomplete(plan, store, cached)
    coming = coming or {}
    blob_inputs = getattr(stage, "blob_inputs", BLOB_TABLES)  # an input made again from its own input needs no blob
    inputs: dict[str, set[str]] = {}
    ready: list[Job] = []
    waiting: dict[tuple[str, str], list[Job]] = defaultdict(list)
    for key in unique:  # plan order; a job is read only where it has work (a rerun reads none)
        if key not in needed:
            continue
        job = unique[key]
        source = stage.upstream(job)
        if source is not None:
            table, upstream_key = source
            if upstream_key in coming.get(table, ()):  # made in this pass, or made again for its passes
                waiting[source].append(job)  # (a stored render whose truth passes are redone): wait for it
                continue
            if table not in inputs:
                inputs[table] = store.keys(table)
            if upstream_key not in inputs[table] or (table in blob_inputs and not store.blob_path(upstream_key).exists()):
                continue  # skipped: its input failed or was never made
        ready.append(job)
    return ready, dict(waiting)


def stage_counts(stage: Stage, plan: Plan, store: Store, found: Found | None = None) -> tuple[int, int]:
    """(distinct keys ``plan`` needs at ``stage``, how many the store holds complete), from
    ``found`` where the caller already looked (:func:`rows_and_cached`)."""
    if found is None and not store.key_set(stage.table):  # nothing stored yet: count the keys, find none
        return _distinct_keys(stage, plan), 0
    cached = (found if found is not None else rows_and_cached(stage, plan, store))[1]
    return len(unique_jobs(stage, plan.jobs)), len(cached - stage.incomplete(plan, store, cached))


def _distinct_keys(stage: Stage, plan: Plan) -> int:
    """How many distinct keys ``plan`` has at ``stage``: from its columns where the stage reads
    them there (a set of 10⁶ keys, without the first job of each that :func:`unique_jobs` finds)."""
    keys_of = _keys_of(stage)
    if keys_of is None or not isinstance(plan.jobs, JobList):
        return len(unique_jobs(stage, plan.jobs))
    distinct = set(keys_of(plan.jobs))
    return len(distinct) - (None in distinct)


def discard_damaged(stage: Stage, store: Store, cached: set[str]) -> set[str]:
    """The ``cached`` blobs of ``stage`` found damaged, discarded with one warning.

    A stage reading a blob checks its digest, but a blob whose downstream results are all cached
    is never read again: without this a damaged one would stay in the store until ``cache
    verify``. Discarded here, it is recomputed in the same pass (downstream keys are unchanged).
    """
    damaged = damaged_blobs(store, stage.table, cached)
    store.discard(stage.table, damaged, DAMAGED)
    return damaged


@dataclass
class StagePass:
    """One stage's share of a pass: its outcome so far, and the jobs it has to compute.

    Attributes:
        ready: jobs whose input is stored (or that read none).
        waiting: jobs whose input an upstream stage of the pass has still to store, by (table, key).
        damaged: upstream blobs its compute found damaged, by table.
    """

    stage: Stage
    outcome: StageOutcome
    ready: list[Job]
    waiting: dict[tuple[str, str], list[Job]]
    seconds: float = 0.0  # spent before computing (finding what is cached, discarding damaged blobs)
    damaged: dict[str, set[str]] = field(default_factory=lambda: defaultdict(set))

    @property
    def keys(self) -> set[str]:
        """The keys this stage computes in the pass."""
        return {self.stage.key(j) for j in self.ready} | {self.stage.key(j) for js in self.waiting.values() for j in js}


def begin(stage: Stage, plan: Plan, store: Store, coming: Mapping[str, set[str]],
          found: Found | None = None) -> StagePass:
    """What ``stage`` must compute in a pass whose earlier stages will store ``coming`` (by table);
    ``found``: what :func:`rows_and_cached` gave, when nothing was written since (it is consumed)."""
    started = time.perf_counter()
    unique = unique_jobs(stage, plan.jobs)
    have, cached = found if found is not None else rows_and_cached(stage, plan, store)
    if stage.owns_blobs:  # rows whose blob has gone (deleted, quarantined): computed again, one row each
        store.drop_rows(stage.table, have - cached)
        cached -= discard_damaged(stage, store, cached)
    ready, waiting = split_to_do(stage, plan, store, cached, coming)
    run = StagePass(stage, StageOutcome(getattr(stage, "title", stage.name), total=len(unique)), ready, waiting)
    keys = run.keys
    run.outcome.cached = len(cached - keys)
    run.outcome.skipped = run.outcome.total - run.outcome.cached - len(keys)
    run.seconds = time.perf_counter() - started
    return run


class Writers:
    """The segment writers of a pass, flushed together in stage order every few seconds.

    Flushing upstream tables first means that a row on disk always has its upstream rows on disk
    too: a kill at any moment never leaves a prediction whose image row was lost with the kill
    (the image would be made again, from pixels the prediction never saw).
    """

    def __init__(self, store: Store, schemas: Sequence[tuple[str, pa.Schema]]) -> None:
        never = float("inf")  # the writers never flush on their own: this class orders flushes
        self._writers: dict[str, SegmentWriter] = {
            table: store.segment_writer(table, schema, every=never, max_rows=2**62) for table, schema in schemas}
        self._waiting = 0
        self._last = time.monotonic()

    def add(self, table: str, row: dict[str, Any]) -> None:
        self._writers[table].add(row)
        self._waiting = max(self._waiting, len(self._writers[table].rows))
        if self._waiting >= FLUSH_ROWS or time.monotonic() - self._last >= FLUSH_SECONDS:
            self.flush()

    def flush(self) -> None:
        for writer in self._writers.values():  # in stage order (dicts keep insertion order)
            writer.flush()
        self._waiting, self._last = 0, time.monotonic()


_DONE = object()  # a stage's thread has yielded its last item


class _Pass:
    """Runs the stages of one pass together; everything it records, it records in one thread."""

    def __init__(self, runs: list[StagePass], plan: Plan, store: Store, bars: list[StageProgress],
                 writers: Writers, fresh: dict[str, dict[str, Verified]] | None = None) -> None:
        self.runs, self.plan, self.store, self.bars, self.writers = runs, plan, store, bars, writers
        self.fresh = fresh if fresh is not None else defaultdict(dict)  # blobs written, read back: see _record
        self.recorded: dict[str, dict[str, dict[str, Any]]] = {
            table: {} for r in runs for table in (r.stage.table, *r.stage.side_tables)}
        self.running = [bool(r.ready or r.waiting) for r in runs]  # stages still computing
        self.feeds = [Feed(store, self.recorded, r.ready, more=bool(r.waiting),
                           computing=tuple(b.stage.name for b, busy in zip(runs[:i], self.running) if busy))
                      for i, r in enumerate(runs)]
        self.events: queue.Queue = queue.Queue()
        self.threads: list[threading.Thread] = []
        self.started = time.perf_counter()

    def run(self) -> None:
        """Compute every stage's jobs: the first stage here, the others in threads, fed as inputs land."""
        for i in range(1, len(self.runs)):
            if self.running[i]:
                thread = threading.Thread(target=self._produce, args=(i,), name=f"sweep3d-{self.runs[i].stage.name}",
                                          daemon=True)
                self.threads.append(thread)
                thread.start()
        interrupted = False
        try:
            if self.running[0]:
                with closing(self.runs[0].stage.compute(self.feeds[0], self.plan, self.store)) as items:
                    for item in items:
                        self._record(0, item)
                        self._drain(block=False)
                self._done(0)
            while any(self.running):
                self._drain(block=True)
        except KeyboardInterrupt:  # Ctrl-C or SIGTERM: the user wants out, even past a plug-in that hangs
            interrupted = True
            raise
        finally:
            self._stop(INTERRUPTED_JOIN_SECONDS if interrupted else JOIN_SECONDS)

    def _stop(self, seconds: float) -> None:
        """Cancel the stages' feeds and give each thread up to ``seconds`` to end its item."""
        for feed in self.feeds:
            feed.cancel()  # a no-op for the stages that are done
        for thread in self.threads:
            thread.join(seconds)

    def _produce(self, index: int) -> None:
        """A stage's thread: compute its feed, passing each item to the recording thread."""
        run = self.runs[index]
        try:
            for item in run.stage.compute(self.feeds[index], self.plan, self.store):
                self.events.put((index, item))
        except Cancelled:
            return
        except BaseException as exc:  # noqa: BLE001  (raised again in the recording thread)
            self.events.put((index, exc))
            return
        self.events.put((index, _DONE))

    def _drain(self, block: bool) -> None:
        """Record what the stages' threads have computed (waiting for something when ``block``)."""
        while True:
            try:
                index, item = self.events.get(block=block, timeout=0.25 if block else None)
            except queue.Empty:
                return
            if isinstance(item, BaseException):
                raise item
            if item is _DONE:
                self._done(index)
            else:
                self._record(index, item)
            block = False  # then take whatever else is there

    def _record(self, index: int, item: Computed) -> None:
        """Count one item, write its rows, and hand its key to the stages waiting for it."""
        run = self.runs[index]
        outcome, stage = run.outcome, run.stage
        if item.error is not None:
            outcome.failed += 1
            outcome.errors.append(f"{stage.name} {item.key[:12]}: {item.error}")
        elif item.damaged is not None:
            run.damaged[item.damaged[0]].add(item.damaged[1])
            outcome.skipped += 1
        else:
            outcome.computed += 1
            if item.row is not None:
                self.recorded[stage.table][item.key] = item.row
                self.writers.add(stage.table, item.row)
                if stage.owns_blobs and item.row.get(DIGEST_COLUMN):
                    self._written(stage.table, item.key, item.row[DIGEST_COLUMN])
            for row in item.rows:
                self.recorded[stage.table][row[KEY_COLUMN[stage.table]]] = row
                self.writers.add(stage.table, row)
            for table, row in item.side.items():
                self.recorded.setdefault(table, {})[row[KEY_COLUMN[table]]] = row
                self.writers.add(table, row)
            for later, feed in zip(self.runs[index + 1:], self.feeds[index + 1:]):
                for job in later.waiting.pop((stage.table, item.key), ()):
                    feed.put(job)
        self.bars[index].advance(failed=item.error is not None)

    def _written(self, table: str, key: str, digest: str) -> None:
        """Remember the blob a stage has just written as verified, when it reads back with the
        digest its row records: the memo of verified blobs gets it at the pass's end, and the
        first rerun need not hash it (a write after this read shows as another file state)."""
        verified = verified_now(self.store.blob_file(key))
        if verified is not None and verified.digest == digest:
            self.fresh[table][key] = verified

    def _done(self, index: int) -> None:
        """Stage ``index`` has computed everything: what still waits for it is skipped, and a
        stage whose upstream stages are all done gets no more jobs."""
        run = self.runs[index]
        self.running[index] = False
        run.seconds += time.perf_counter() - self.started
        for later in range(index + 1, len(self.runs)):
            self.feeds[later].finish(run.stage.name)
            waiting = self.runs[later].waiting
            for source in [s for s in waiting if s[0] == run.stage.table]:
                self.runs[later].outcome.skipped += len(waiting.pop(source))
            if not any(self.running[:later]):
                for jobs in waiting.values():  # inputs from a table no stage of the pass writes
                    self.runs[later].outcome.skipped += len(jobs)
                waiting.clear()
                self.feeds[later].close()


def run_pass(stages: Sequence[Stage], plan: Plan, store: Store, progress: RunProgress,
             found: Mapping[str, Found] | None = None) -> list[StageOutcome]:
    """Run ``stages`` once over ``plan``, overlapped: each computes what the store lacks as its
    inputs land, and records it as it comes (``found``: by table, what :func:`rows_and_cached`
    gave the caller, with nothing written since). Returns each stage's outcome."""
    runs: list[StagePass] = []
    coming: dict[str, set[str]] = {}
    for stage in stages:
        runs.append(begin(stage, plan, store, coming, (found or {}).get(stage.table)))
        coming[stage.table] = runs[-1].keys
    store.forget_states()  # blobs are written from here on: a snapshot of their states would go stale
    busy = [bool(r.ready or r.waiting) for r in runs]
    schemas = [item for r, b in zip(runs, busy) if b
               for item in [(r.stage.table, r.stage.schema(plan)), *r.stage.side_tables.items()]]
    with ExitStack() as stack:
        bars = [stack.enter_context(progress.stage(getattr(r.stage, "title", r.stage.name), len(r.keys), r.outcome.cached))
                if b else StageProgress(None, None) for r, b in zip(runs, busy)]
        fresh: dict[str, dict[str, Verified]] = defaultdict(dict)
        stack.callback(_remember_fresh, store, fresh)  # after the rows are flushed (the last callback runs first)
        writers = Writers(store, schemas)
        stack.callback(writers.flush)
        _Pass(runs, plan, store, bars, writers, fresh).run()
    _discard_damaged_inputs(runs, store)
    for run in runs:
        run.outcome.seconds = run.seconds
    return [r.outcome for r in runs]


def _remember_fresh(store: Store, fresh: dict[str, dict[str, Verified]]) -> None:
    """Add the blobs the pass wrote and read back to the memo of verified blobs, one write per table."""
    for table, verified in fresh.items():
        remember_verified(store, table, verified)


def _discard_damaged_inputs(runs: list[StagePass], store: Store) -> None:
    """Discard the upstream blobs the stages found damaged (each counted once, by the first
    stage that found it), so the run's next pass computes them again."""
    seen: set[tuple[str, str]] = set()
    for run in runs:
        for table, keys in run.damaged.items():
            new = {k for k in keys if (table, k) not in seen}
            if new:
                seen |= {(table, k) for k in new}
                store.discard(table, new, DAMAGED)
                run.outcome.repaired += len(new)


def run_stage(stage: Stage, plan: Plan, store: Store, progress: RunProgress) -> StageOutcome:
    """Compute what ``plan`` needs at ``stage`` and the store lacks; record it as it comes."""
    return run_pass([stage], plan, store, progress)[0]


def run_stages(stages: Sequence[Stage], plan: Plan, store: Store, progress: RunProgress,
               strict: bool = False, overlap: bool = False, found: Mapping[str, Found] | None = None) -> list[StageOutcome]:
    """Run ``stages`` over ``plan``; again while one repaired a damaged blob.

    Args:
        strict: raise on a failed key instead of reporting it (for callers that need every
            result, such as the bench and the contact sheet).
        found: for the first pass, by table, what :func:`rows_and_cached` gave the caller with
            nothing written since (a run looks before it starts, to say what it will render).
        overlap: run the stages together, each on what the ones before have stored so far (as
            a run does); else one after the other, each over the whole plan: the same keys, rows
            and counts, and renders timed without inference beside them (as the bench needs).

    Raises:
        UserError: with ``strict``, naming the stage, the setting's first error and the count.
    """
    outcomes: list[StageOutcome] = []
    for _ in range(1 + REPAIR_PASSES):
        if overlap:
            now = run_pass(stages, plan, store, progress, found)
        else:
            now = [run_pass([stage], plan, store, progress, found)[0] for stage in stages]
        found = None  # the pass wrote: look again
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


def add_outcomes(before: list[StageOutcome], now: list[StageOutcome]) -> list[StageOutcome]:
    """Sum each stage's outcomes over passes on different keys (models framed apart render
    their own images): unlike :func:`merge_outcomes`, totals and cached keys add up."""
    if not before:
        return now
    return [StageOutcome(old.stage, total=old.total + new.total, cached=old.cached + new.cached,
                         computed=old.computed + new.computed, failed=old.failed + new.failed,
                         skipped=old.skipped + new.skipped, seconds=old.seconds + new.seconds,
                         errors=old.errors + new.errors, repaired=old.repaired + new.repaired)
            for old, new in zip(before, now)]
