"""A pool of persistent render worker processes, driven from the parent (which never imports bpy).

Jobs arrive grouped by scene, ordered world by world; a group goes to one worker so the scene is
loaded once, and each worker takes its groups from its own contiguous share of that order
(:class:`Shares`), so it changes world as rarely as the order allows. A worker that dies or
exceeds the per-job timeout is replaced and its unfinished jobs are retried once; a worker that
retires between jobs (it reached ``[render] worker_memory`` or ``worker_jobs``: see
:class:`WorkerLimits`) is replaced too, and a fresh one renders the rest of its list: no job is
lost or rendered twice. With a GPU device and several workers, each renders on its own GPU
(its slot's number, modulo the GPUs there are). Scratch files
are removed when the pool closes, also on Ctrl-C, and a killed run's by the next run
(:func:`remove_stale_scratch`). Workers die with their parent.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import shutil
import signal
import tempfile
import time
from collections import Counter, deque
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any, Iterator

from sweep3d.errors import RenderError, UserError
from sweep3d.registry import is_user_plugin
from sweep3d.stages.render.device import KERNEL_GRACE, prepare_gpu_environment
from sweep3d.stages.render.protocol import (
    NO_LIMITS,
    Editing,
    Fatal,
    Idle,
    Ready,
    RenderJob,
    RenderReply,
    RenderSettings,
    Retired,
    Started,
    WorkerLimits,
)
from sweep3d.stages.render.worker import worker_main

SCRATCH_PREFIX = "sweep3d-"  # + the parent's pid: a later run can tell a killed run's folder
START_TIMEOUT = 120.0  # seconds a worker may take to import bpy and build its scene


class Shares:
    """Groups split into one contiguous share per worker slot, balanced by job count.

    A worker takes the next group of its own share; once its share is done it takes the last
    group of the largest share left, the one that share's owner would reach last.
    """

    def __init__(self, groups: list[list[RenderJob]], slots: int) -> None:
        total = sum(len(g) for g in groups)
        self.shares: list[deque[list[RenderJob]]] = [deque() for _ in range(max(slots, 1))]
        done = 0
        for group in groups:  # a group goes to the share its middle job falls in
            slot = int((done + len(group) / 2) * len(self.shares) / max(total, 1))
            self.shares[min(slot, len(self.shares) - 1)].append(group)
            done += len(group)

    def __bool__(self) -> bool:
        return any(self.shares)

    def take(self, slot: int) -> list[RenderJob] | None:
        """The next group for the worker in ``slot``, or None when every share is done."""
        if self.shares[slot]:
            return self.shares[slot].popleft()
        largest = max(self.shares, key=lambda share: sum(len(g) for g in share))
        return largest.pop() if largest else None

    def put_back(self, slot: int, group: list[RenderJob]) -> None:
        """Return ``group`` to the front of ``slot``'s share (a dead worker's unfinished jobs)."""
        self.shares[slot].appendleft(group)


@dataclass
class _Worker:
    process: Any
    conn: Connection
    slot: int
    task: list[RenderJob] | None = None
    done: set[str] = field(default_factory=set)
    current: str | None = None
    editing: str | None = None  # the user's control whose edit() it runs (Editing), by label
    started: float = 0.0
    retired: Retired | None = None  # it reached a limit after a job and exits
    rendered: int = 0  # jobs it has answered, over all its lists


class RenderPool:
    """Persistent worker processes (a :class:`RenderExecutor`); use as a context manager and call
    :meth:`run`."""

    def __init__(self, settings: RenderSettings, workers: int = 1, timeout: float = 600.0,
                 limits: WorkerLimits = NO_LIMITS) -> None:
        self.settings = settings
        self.n_workers = workers
        self.timeout = timeout
        self.limits = limits
        prepare_gpu_environment(settings.device)
        self.recycled: Counter[str] = Counter()  # workers retired between jobs, by the limit reached
        self.ctx = mp.get_context("spawn")
        root = scratch_root()
        remove_stale_scratch(root)
        self.scratch = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{os.getpid()}-", dir=root))
        self.workers: list[_Worker] = []
        self._started: tuple[Any, Connection] | None = None  # slot 0's process, started ahead (prestart)

    def __enter__(self) -> "RenderPool":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def prestart(self) -> None:
        """Start the first worker's process now without waiting for it, so that its import of
        Blender and its scene overlap the caller's own work; :meth:`run` waits for it."""
        if not self.workers and self._started is None:
            self._started = self._start(0)

    def _start(self, slot: int) -> tuple[Any, Connection]:
        parent, child = self.ctx.Pipe()
        gpu = slot if self.settings.device != "cpu" and self.n_workers > 1 else None  # one GPU per worker
        process = self.ctx.Process(
            target=worker_main, args=(child, self.settings, str(self.scratch), self.limits, gpu), daemon=True,
            name="sweep3d-render"
        )
        process.start()
        child.close()
        return process, parent

    def _spawn(self, slot: int) -> _Worker:
        if slot == 0 and self._started is not None:  # started ahead by prestart
            (process, parent), self._started = self._started, None
        else:
            process, parent = self._start(slot)
        message = _first_message(parent, process)
        if not isinstance(message, Ready):
            process.kill()
            process.join(5)
            if message.user:  # the worker's own line says what to fix
                raise UserError(message.message)
            raise RenderError(f"render worker {message.message}")
        return _Worker(process, parent, slot)

    def run(self, groups: list[list[RenderJob]]) -> Iterator[RenderReply]:
        """Render every job of every group, yielding one reply per job as it finishes."""
        groups = [g for g in groups if g]
        queue = Shares(groups, min(self.n_workers, len(groups)))
        retried: set[str] = set()
        while len(self.workers) < len(queue.shares) and groups:
            self.workers.append(self._spawn(len(self.workers)))
        while queue or any(w.task is not None for w in self.workers):
            for worker in self.workers:
                if worker.task is None and queue:
                    worker.task, worker.done, worker.current = queue.take(worker.slot), set(), None
                    worker.conn.send(worker.task)
            busy = [w for w in self.workers if w.task is not None]
            ready = wait([w.conn for w in busy] + [w.process.sentinel for w in busy], timeout=1.0)
            for worker in busy:
                if worker.conn in ready:
                    try:
                        while worker.retired is None and worker.conn.poll():
                            yield from self._handle(worker, worker.conn.recv())
                    except (EOFError, OSError):
                        pass  # died mid-message: handled below as a dead worker
                if worker.retired is not None:
                    self._recycle(worker, queue)
                    continue
                timed_out = worker.current is not None and time.monotonic() - worker.started > self.allowed(worker)
                if worker.task is not None and (not worker.process.is_alive() or timed_out):
                    yield from self._replace(worker, queue, retried, timed_out)

    def allowed(self, worker: _Worker) -> float:
        """Seconds ``worker``'s current job may take: ``timeout``, and on a GPU worker's first job
        the time its driver may spend compiling Cycles' kernels too."""
        compiles = self.settings.device != "cpu" and worker.rendered == 0
        return self.timeout + (KERNEL_GRACE if compiles else 0.0)

    def _handle(self, worker: _Worker, message: Started | Editing | RenderReply | Idle | Retired
                ) -> Iterator[RenderReply]:
        if isinstance(message, Started):
            worker.current, worker.started, worker.editing = message.render_key, time.monotonic(), None
        elif isinstance(message, Editing):
            worker.editing = message.control
        elif isinstance(message, RenderReply):
            worker.done.add(message.render_key)
            worker.rendered += 1
            worker.current = worker.editing = None
            yield message
        elif isinstance(message, Idle):
            worker.task = None
        elif isinstance(message, Retired):
            worker.retired = message

    def _recycle(self, worker: _Worker, queue: Shares) -> None:
        """Replace a worker that retired between jobs: the rest of its list goes first to the fresh
        worker in its slot (not a retry: none of those jobs had started)."""
        worker.process.join(5)  # it exits by itself after saying so
        if worker.process.is_alive():
            worker.process.kill()
            worker.process.join(5)
        self.recycled[worker.retired.reason] += 1
        self.workers.remove(worker)
        leftover = [job for job in worker.task or [] if job.render_key not in worker.done]
        if leftover:
            queue.put_back(worker.slot, leftover)
        if queue:
            self.workers.append(self._spawn(worker.slot))

    def _replace(self, worker: _Worker, queue: Shares, retried: set[str],
                 timed_out: bool) -> Iterator[RenderReply]:
        """Replace a dead or stuck worker; retry its unfinished jobs once, fail the culprit twice."""
        culprit = worker.current
        reason = f"render took longer than {self.timeout:g} s" if timed_out else died(worker)
        worker.process.kill()
        worker.process.join(5)
        leftover = [job for job in worker.task or [] if job.render_key not in worker.done]
        self.workers.remove(worker)
        retry = []
        for job in leftover:
            key = job.render_key
            if key == culprit and key in retried:
                yield _failure(job, reason, timed_out, self.timeout, None if timed_out else worker.editing)
            else:
                if key == culprit:
                    retried.add(key)
                retry.append(job)
        if retry:
            queue.put_back(worker.slot, retry)
        if queue:  # also when only other groups are left: a pool never runs out of workers
            self.workers.append(self._spawn(worker.slot))

    def close(self) -> None:
        if self._started is not None:  # started ahead and never given a job: nothing of it to keep
            process, conn = self._started
            self._started = None
            process.kill()
            process.join(5)
            conn.close()
        for worker in self.workers:
            try:
                worker.conn.send(None)
            except (OSError, ValueError):
                pass
        for worker in self.workers:
            worker.process.join(timeout=5)
            if worker.process.is_alive():
                worker.process.kill()
        self.workers = []
        shutil.rmtree(self.scratch, ignore_errors=True)


def died(worker: _Worker) -> str:
    """Why ``worker`` is gone, naming the user's control in whose ``edit()`` it died."""
    cause = death_cause(worker.process.exitcode)
    if worker.editing is not None:
        return f"{worker.editing} ended the render worker in edit() ({cause})"
    return f"render worker died ({cause})"


def _failure(job: RenderJob, reason: str, timed_out: bool, timeout: float, killer: str | None = None) -> RenderReply:
    """The reply for a job that failed its worker twice: a user's control that edits the scene is
    the likely cause of a job that never ends, and the cause of a worker that died in its
    ``edit()`` (``killer``: os._exit, a crash in Blender), so it is named (kind "plugin": the run stops)."""
    if killer is not None:
        return RenderReply(job.render_key, False, kind="plugin",
                           error=f"{reason}, twice; a plug-in must not end its process (os._exit, a crash in "
                                 "Blender): raise an exception to fail")
    editing = [c for c, _ in job.controls if is_user_plugin(c.type_name) and c.edits_scene] if timed_out else []
    if editing:
        names = ", ".join(f"{c.type_name!r} (id {c.id!r})" for c in editing)
        return RenderReply(job.render_key, False, kind="plugin",
                           error=f"control {names} did not finish its job within render.timeout = {timeout:g} s, "
                                 "twice: its edit() may hang; raise render.timeout if it is only slow")
    return RenderReply(job.render_key, False, error=reason)


def _first_message(conn: Connection, process: Any) -> Ready | Fatal:
    """The worker's first message, or a :class:`Fatal` saying why none came: it died while
    starting (the OOM killer during ``import bpy``, say) or took longer than ``START_TIMEOUT``."""
    if not wait([conn, process.sentinel], timeout=START_TIMEOUT):
        return Fatal(f"did not start within {START_TIMEOUT:g} s")
    try:
        if conn.poll(1.0):  # a message sent just before dying is still there to read
            message = conn.recv()
            if isinstance(message, Fatal) and not message.user:
                return Fatal(f"failed to start: {message.message}")
            return message
    except (EOFError, OSError):
        pass  # the pipe closed without a message: the process died
    process.join(5)
    return Fatal(f"died while starting ({death_cause(process.exitcode)})")


def death_cause(exitcode: int | None) -> str:
    """How a worker process ended, in words: its exit code, or the signal that killed it."""
    if exitcode is None:
        return "still running, not answering"
    if exitcode >= 0:
        return f"exit code {exitcode}"
    try:
        name = signal.Signals(-exitcode).name
    except ValueError:
        name = f"signal {-exitcode}"
    return f"killed by {name}: out of memory?" if -exitcode == signal.SIGKILL else f"killed by {name}"


def remove_stale_scratch(root: Path) -> int:
    """Remove scratch folders left by runs that were killed (SIGKILL skips every clean-up):
    each is named after its process, which no longer exists. Returns how many were removed."""
    removed = 0
    for folder in root.glob(f"{SCRATCH_PREFIX}*-*"):
        pid = folder.name[len(SCRATCH_PREFIX):].split("-", 1)[0]
        if pid.isdigit() and not _alive(int(pid)):
            shutil.rmtree(folder, ignore_errors=True)
            removed += 1
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def scratch_root() -> Path:
    """Where workers' scratch folders go: memory (``/dev/shm``) where there is one."""
    shm = Path("/dev/shm")
    return shm if shm.is_dir() else Path(tempfile.gettempdir())
