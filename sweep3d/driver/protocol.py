"""The stage protocol: what render, postprocess and infer implement (:class:`Stage`), what a stage
is handed to compute (:class:`Feed`) and what it yields per job (:class:`Computed`).

Apart from the loop that runs stages (:mod:`sweep3d.driver.loop`), so a stage depends on the
protocol only, never on the driver.
"""

from __future__ import annotations

import threading
from collections import ChainMap
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Iterator, Mapping, Protocol

import pyarrow as pa

from sweep3d.cache import DIGEST_COLUMN, Store
from sweep3d.driver.jobs import Job, Plan


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
            discarded after the pass, and recomputed by the run's next pass.
        rows: the stage table's rows when it records several per job, each under its own key
            (the stability check: one per change); ``key`` is then the job's first row's.
    """

    key: str
    row: dict[str, Any] | None = None
    side: dict[str, dict[str, Any]] = field(default_factory=dict)
    error: str | None = None
    damaged: tuple[str, str] | None = None
    rows: list[dict[str, Any]] = field(default_factory=list)  # last: callers build the others by position


class Cancelled(Exception):
    """Raised in a stage's thread by its :class:`Feed` when the pass stops (a stage failed, Ctrl-C)."""


class Feed:
    """The jobs one stage computes in a pass, handed over as their inputs are stored.

    Iterating waits for more jobs until the stages upstream are done, so a stage computes while
    they still run; iterating again replays what came so far (the render stage walks its jobs
    more than once, all of them there from the start). :meth:`column` and :meth:`digests` read
    upstream rows: the ones this pass recorded, else the store's, because a job may arrive before
    its input's row is flushed.
    """

    def __init__(self, store: Store, recorded: Mapping[str, dict[str, dict[str, Any]]], jobs: Iterable[Job] = (),
                 more: bool = False, computing: tuple[str, ...] = ()) -> None:
        self._store, self._recorded = store, recorded
        self._jobs = list(jobs)
        self._open, self._cancelled = more, False
        # Which of the stages before this one compute in the pass: fixed, unlike ``more`` (which
        # says how fast they went), so what a stage chooses from it is the same run to run.
        self.computing = computing
        self.finished: set[str] = set()  # of those, the ones done computing so far (see finish)
        self._changed = threading.Condition()

    def finish(self, stage: str) -> None:
        """Stage ``stage`` upstream is done computing; it may still hand jobs over through the
        stages between (how fast the stages went: nothing stored may depend on it)."""
        with self._changed:
            self.finished.add(stage)

    def put(self, job: Job) -> None:
        with self._changed:
            self._jobs.append(job)
            self._changed.notify_all()

    def close(self) -> None:
        """No more jobs will come: iteration ends once it has yielded the ones here."""
        with self._changed:
            self._open = False
            self._changed.notify_all()

    def cancel(self) -> None:
        """Stop the stage: iterating raises :class:`Cancelled`."""
        with self._changed:
            self._cancelled = True
            self._changed.notify_all()

    def __iter__(self) -> Iterator[Job]:
        i = 0
        while True:
            with self._changed:
                while i >= len(self._jobs) and self._open and not self._cancelled:
                    self._changed.wait()
                if self._cancelled:
                    raise Cancelled
                if i >= len(self._jobs):
                    return
                job = self._jobs[i]
            i += 1
            yield job

    def __len__(self) -> int:
        return len(self._jobs)

    @property
    def more(self) -> bool:
        """Whether more jobs may still come (stages upstream are still computing)."""
        return self._open

    def column(self, table: str, column: str) -> Mapping[str, Any]:
        """Key → ``column`` of its row in ``table`` (live: rows recorded later show up too)."""
        return ChainMap(_Recorded(self._recorded.get(table, {}), lambda row: row[column]),
                        self._store.column_map(table, column))

    def digests(self, table: str, column: str = DIGEST_COLUMN) -> Mapping[str, set[str]]:
        """Key → the blob digests its rows in ``table`` record in ``column`` (live, as :meth:`column`;
        a side table's rows, such as ``truths``, are recorded too)."""
        return ChainMap(_Recorded(self._recorded.get(table, {}), lambda row: {row[column]} if row.get(column) else set()),
                        self._store.digests(table, column))


class _Recorded(Mapping[str, Any]):
    """A read-only view of one value of the rows a pass recorded (missing value: missing key)."""

    def __init__(self, rows: dict[str, dict[str, Any]], value: Callable[[dict[str, Any]], Any]) -> None:
        self._rows, self._value = rows, value

    def __getitem__(self, key: str) -> Any:
        return self._value(self._rows[key])

    def __contains__(self, key: object) -> bool:
        try:
            self[key]  # type: ignore[index]
        except KeyError:
            return False
        return True

    def __iter__(self) -> Iterator[str]:
        return iter(list(self._rows))

    def __len__(self) -> int:
        return len(self._rows)


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
        """The job's key at this stage (a function of the job alone); None when it has nothing to do here.

        A stage may also define ``keys_of(jobs: JobList) -> list[str | None]``, :meth:`key` of
        every job read from the plan's columns (``JobList.key_column``), so that finding the
        distinct keys of 10⁶ jobs makes no job."""

    def upstream(self, job: Job) -> tuple[str, str] | None:
        """(table, key) of the stored blob the job reads, or None when it reads none."""

    def incomplete(self, plan: Plan, store: Store, cached: set[str]) -> set[str]:
        """Cached keys to compute again for something of theirs the store lacks (e.g. a pass).

        A stage whose rows' columns depend on the plan (the infer stage's, on its evaluator) may
        also define ``required_columns(plan) -> (columns, whose)``: see :func:`rows_and_cached`."""

    def compute(self, todo: Feed, plan: Plan, store: Store) -> Iterator[Computed]:
        """Compute ``todo`` (one job per key, coming as their inputs land), yielding one
        :class:`Computed` per job; it may run in a thread of its own."""
