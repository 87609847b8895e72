"""A pool of persistent render worker processes, driven from the parent (which never imports bpy).

Jobs arrive grouped by scene, ordered world by world; a group goes to one worker so the scene is
loaded once, and each worker takes its groups from its own contiguous share of that order
(:class:`Shares`), so it changes world as rarely as the order allows. A worker that dies or
exceeds the per-job timeout is replaced and its unfinished jobs are retried once, but a job whose
control's ``edit`` outlives ``edit_timeout`` fails at once, naming the control; a worker that
retires between jobs (it reached ``[render] worker_memory`` or ``worker_jobs``: see
:class:`WorkerLimits`) is replaced too, and a fresh one renders the rest of its list: no job is
lost or rendered twice. With a GPU device and several workers, each renders on its own GPU
(its slot's number, modulo the GPUs there are). Scratch files
are removed when the pool closes, also on Ctrl-C, and a killed run's by the next run
(:func:`remove_stale_scratch`). Workers are :class:`~.child.Child` processes: they never run the
user's ``__main__``, die with their parent, and nothing they start outlives them.
"""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Iterator, Literal

from sweep3d.core import RenderError, UserError, control_label, is_user_plugin
from sweep3d.stages.render import early
from sweep3d.stages.render.child import Child
from sweep3d.stages.render.device import KERNEL_GRACE, prepare_gpu_environment
from sweep3d.stages.render.worker import worker_main
from sweep3d.stages.render.worker_protocol import (
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

SCRATCH_PREFIX = "sweep3d-"  # + the parent's pid: a later run can tell a killed run's folder
START_TIMEOUT = 120.0  # seconds a worker may take to import bpy and build its scene
#: What ends a busy worker: a control's edit() past edit_timeout, its job past the timeout, its death.
Trouble = Literal["edit", "timeout", "died"]


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
    process: Child
    conn: Connection
    slot: int
    task: list[RenderJob] | None = None
    done: set[str] = field(default_factory=set)
    current: str | None = None
    started: float = 0.0
    retired: Retired | None = None  # it reached a limit after a job and exits
    editing: str | None = None  # the id of the control whose edit() it runs now
    edit_started: float = 0.0
    rendered: int = 0  # jobs it has answered, over all its lists


class RenderPool:
    """Persistent worker processes (a :class:`RenderExecutor`); use as a context manager and call
    :meth:`run`."""

    def __init__(self, settings: RenderSettings, workers: int = 1, timeout: float = 600.0,
                 limits: WorkerLimits = NO_LIMITS, edit_timeout: float = 60.0) -> None:
        self.settings = settings
        self.n_workers = workers
        self.timeout = timeout
        self.limits = limits
        self.edit_timeout = edit_timeout
        prepare_gpu_environment(settings.device)
        self.recycled: Counter[str] = Counter()  # workers retired between jobs, by the limit reached
        root = scratch_root()
        remove_stale_scratch(root)
        self.scratch = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{os.getpid()}-", dir=root))
        self.workers: list[_Worker] = []
        self._started: tuple[Child, Connection] | None = None  # slot 0's process, started ahead (prestart)
        self._ending: threading.Thread | None = None  # ends the workers after close(wait=False)

    def __enter__(self) -> "RenderPool":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def prestart(self) -> None:
        """Start the first worker's process now without waiting for it, so that its import of
        Blender and its scene overlap the caller's own work; :meth:`run` waits for it."""
        if not self.workers and self._started is None:
            self._started = self._start(0)

    def _start(self, slot: int) -> tuple[Child, Connection]:
        """A fresh worker process (in its own process group: see :mod:`.child`) and its pipe."""
        gpu = slot if self.settings.device != "cpu" and self.n_workers > 1 else None  # one GPU per worker
        args = (self.settings, str(self.scratch), self.limits, gpu)
        process = early.take(self.settings.engine, self.settings.device) if slot == 0 else None
        if process is not None:  # started by the command line before the spec was read, Blender loaded
            process.assign(worker_main, args, "sweep3d-render")
        else:
            process = Child(worker_main, args, "sweep3d-render")
        return process, process.conn

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
                trouble = self._trouble(worker) if worker.task is not None else None
                if trouble is not None:
                    yield from self._replace(worker, queue, retried, trouble)

    def _trouble(self, worker: _Worker) -> Trouble | None:
        """What is wrong with a busy worker, if anything: a control's ``edit`` running past
        ``edit_timeout``, its job past :meth:`allowed`, or its death."""
        now = time.monotonic()
        if worker.editing is not None and now - worker.edit_started > self.edit_timeout:
            return "edit"
        if worker.current is not None and now - worker.started > self.allowed(worker):
            return "timeout"
        return None if worker.process.is_alive() else "died"

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
            worker.editing, worker.edit_started = message.control, time.monotonic()
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
        worker.process.end(5)  # it exits by itself after saying so
        self.recycled[worker.retired.reason] += 1
        self.workers.remove(worker)
        leftover = [job for job in worker.task or [] if job.render_key not in worker.done]
        if leftover:
            queue.put_back(worker.slot, leftover)
        if queue:
            self.workers.append(self._spawn(worker.slot))

    def _replace(self, worker: _Worker, queue: Shares, retried: set[str], trouble: Trouble) -> Iterator[RenderReply]:
        """Replace a dead or stuck worker (with all it started); retry its unfinished jobs once,
        fail the culprit twice, or at once where a control's edit hung (it is named)."""
        culprit, editing, killer = worker.current, worker.editing, _user_editing(worker)
        timed_out = trouble == "timeout"
        reason = f"render took longer than {self.timeout:g} s" if timed_out else died(worker, killer)
        worker.process.kill()
        worker.process.join(5)
        leftover = [job for job in worker.task or [] if job.render_key not in worker.done]
        self.workers.remove(worker)
        retry = []
        for job in leftover:
            key = job.render_key
            if key == culprit and trouble == "edit":
                yield _hung_edit(job, editing, self.edit_timeout)
            elif key == culprit and key in retried:
                yield _failure(job, reason, timed_out, self.timeout, None if timed_out else killer)
            else:
                if key == culprit:
                    retried.add(key)
                retry.append(job)
        if retry:
            queue.put_back(worker.slot, retry)
        if queue:  # also when only other groups are left: a pool never runs out of workers
            self.workers.append(self._spawn(worker.slot))

    def close(self, wait: bool = True) -> None:
        """Stop the workers and remove the scratch folder.

        Args:
            wait: return once they have exited; else return at once, having told them to exit,
                and end them on a thread (:meth:`join` waits for it). Blender's exit takes a
                worker 0.2 s, which the images of a run's last renders need not wait for.
        """
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
        workers, self.workers = self.workers, []
        if wait:
            self._end(workers)
        else:
            self._ending = threading.Thread(target=self._end, args=(workers,), name="sweep3d-render-end")
            self._ending.start()

    def join(self) -> None:
        """Wait until the workers a :meth:`close` without waiting told to exit have ended."""
        if self._ending is not None:
            self._ending.join()
            self._ending = None

    def _end(self, workers: list[_Worker]) -> None:
        for worker in workers:
            worker.process.end(5)  # with whatever it started: nothing outlives the run
        shutil.rmtree(self.scratch, ignore_errors=True)


def died(worker: _Worker, killer: str | None) -> str:
    """Why ``worker`` is gone, naming the user's control (``killer``) in whose ``edit()`` it died."""
    cause = death_cause(worker.process.exitcode)
    if killer is not None:
        return f"{killer} ended the render worker in edit() ({cause})"
    return f"render worker died ({cause})"


def _user_editing(worker: _Worker) -> str | None:
    """The label of the user's control whose ``edit()`` the worker is in (None: none, or a
    built-in's, whose failure is sweep3d's own)."""
    if worker.editing is None:
        return None
    job = next((j for j in worker.task or [] if j.render_key == worker.current), None)
    control = next((c for c, _ in job.controls if c.id == worker.editing), None) if job is not None else None
    return control_label(control) if control is not None and is_user_plugin(control.type_name) else None


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


def _hung_edit(job: RenderJob, control_id: str | None, limit: float) -> RenderReply:
    """The reply for a job whose control's ``edit`` did not return within ``limit`` seconds: one
    line naming the control, where its ``edit`` is and the job's values (kind "plugin": the run
    stops, exit 2). Not retried: the same values would hang again."""
    found = next(((c, p) for c, p in job.controls if c.id == control_id), None)
    if found is None:  # not one of the job's: the worker's word cannot be placed
        return RenderReply(job.render_key, False, kind="plugin", error=f"a control's edit() did not return within "
                                                                       f"render.edit_timeout = {limit:g} s")
    control, params = found
    code = getattr(getattr(type(control), "edit", None), "__code__", None)
    where = f", {Path(code.co_filename).name}:{code.co_firstlineno}" if code is not None else ""
    values = ", ".join(f"{k}={v!r}" for k, v in params.model_dump().items())
    return RenderReply(job.render_key, False, kind="plugin",
                       error=f"control {control.type_name!r} (id {control.id!r}{where}): its edit() did not return "
                             f"within render.edit_timeout = {limit:g} s ({values}); fix it if it hangs, or raise "
                             "render.edit_timeout if it is only slow")


def _first_message(conn: Connection, process: Child) -> Ready | Fatal:
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
