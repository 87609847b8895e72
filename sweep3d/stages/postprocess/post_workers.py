"""Post-processing worker processes: a run's post controls applied on every core, byte for byte
as in the run's own process.

Threads cannot share this work: the ImageNet-C corruptions draw from numpy's global generator,
which the ``corruption`` control seeds for each image, so two threads would interleave their
draws and an image would no longer be the same bytes for its key. Each worker is a process of its
own (:class:`~sweep3d.stages.render.child.Child`: a fresh interpreter sent the run's ``sys.path``,
so a user's ``module:Name`` control beside the spec imports there as it did here; in its own
process group, dying with the run) holding the run's post controls, unpickled once. It is sent
one image at a time (the render's pixels only when they are not the last it was sent: a render's
images come one after another) and answers with what :func:`~.apply.post_image` gives, and the
PNG when the run stores its images.
"""

from __future__ import annotations

import os
import pickle
import socket
import time
import traceback
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any, Sequence

import numpy as np

from sweep3d.core import RenderError, UserError, encode_png8, from_uint8
from sweep3d.spec import ControlInstance
from sweep3d.stages.postprocess.apply import post_image
from sweep3d.stages.postprocess.frame import RenderFrame
from sweep3d.stages.render import Child, death_cause

#: Images sent to a worker ahead of its answers: it has the next at hand while this process, busy
#: or not scheduled on a loaded machine, has yet to read what it made.
DEPTH = 4
#: Bytes a worker's answers may wait in its pipe (a 224² image is 150 kB) before sending blocks it.
PIPE_BYTES = 4 << 20
#: Seconds a worker is given to exit by itself when the stage is done, before it is killed.
GRACE = 5.0


@dataclass(frozen=True)
class Task:
    """One image to make.

    Attributes:
        job: what the stage records the image under (stays in this process).
        pixels: the job's render, uint8 (H, W, 3), as stored.
        frame: the render's passes and camera, for the controls that read them.
        seconds: spent reading its inputs.
    """

    job: Any
    render_key: str
    pixels: np.ndarray
    values: dict[str, dict[str, Any]]
    image_key: str
    frame: RenderFrame | None = None
    seconds: float = 0.0


@dataclass(frozen=True)
class Applied:
    """One image made: ``pixels`` uint8 as stored, ``finite`` (before quantising), its PNG when the
    run stores images, the seconds it took, and the process that made it."""

    pixels: np.ndarray
    finite: bool
    png: bytes | None
    seconds: float
    pid: int


class Applier:
    """Applies the post controls to one image after another, keeping the last render as floats
    (one decode for all its images). The same in the run's process and in a worker."""

    def __init__(self, post: Sequence[ControlInstance], encode: bool) -> None:
        self.post, self.encode = list(post), encode
        self._last: tuple[str, np.ndarray] | None = None

    def __call__(self, render_key: str, pixels: np.ndarray | None, values: dict[str, dict[str, Any]],
                 image_key: str, frame: RenderFrame | None) -> Applied:
        """Make one image; ``pixels`` None: the render is the last one given."""
        started = time.perf_counter()
        if pixels is not None and (self._last is None or self._last[0] != render_key):
            self._last = (render_key, from_uint8(pixels))
        assert self._last is not None and self._last[0] == render_key, "a worker was sent no render"
        made, finite = post_image(self._last[1].copy(), self.post, values, image_key, frame)  # a copy: controls may
        png = encode_png8(made) if self.encode else None                                   # change it in place
        return Applied(made, finite, png, time.perf_counter() - started, os.getpid())

    def task(self, task: Task) -> Applied:
        return self(task.render_key, task.pixels, task.values, task.image_key, task.frame)


def shippable(post: Sequence[ControlInstance]) -> bytes | None:
    """The post controls pickled for the workers; None when a worker could not load one (a class
    defined in a script's or a notebook's ``__main__``, or in a function; an instance holding a
    lock): they stay here, where they always could run."""
    if any(type(inst.control).__module__ in ("__main__", "__mp_main__") for inst in post):
        return None  # it pickles by reference, but a worker runs no one's __main__
    try:
        return pickle.dumps(list(post))
    except Exception:  # noqa: BLE001  (any failure: the run's process applies them, as it always could)
        return None


class _Worker:
    """One worker process and what it has been sent."""

    def __init__(self, blob: bytes, encode: bool) -> None:
        self.child = Child(serve, (blob, encode), name="sweep3d-post")
        self.ready = False
        self.sent: dict[int, Task] = {}  # sequence number -> task, unanswered
        self.render: str | None = None  # the render key it holds


class PostWorkers:
    """Worker processes applying post controls, started at once and ready when each says so;
    :meth:`close` ends them all (also on an error or Ctrl-C: none outlives the stage)."""

    def __init__(self, blob: bytes, count: int, encode: bool) -> None:
        self.workers: list[_Worker] = []
        try:
            for _ in range(count):
                self.workers.append(_Worker(blob, encode))
        except BaseException:
            self.close(graceful=False)
            raise

    @property
    def live(self) -> bool:
        """Whether any worker is starting or working (none may have loaded the controls)."""
        return bool(self.workers)

    def idle(self) -> list[_Worker]:
        """The ready workers that can take another image."""
        return [w for w in self.workers if w.ready and len(w.sent) < DEPTH]

    def send(self, seq: int, task: Task) -> None:
        """Give ``task`` to the idle worker that holds its render, else to the least busy one."""
        idle = self.idle()
        worker = min(idle, key=lambda w: (w.render != task.render_key, len(w.sent)))
        pixels = None if worker.render == task.render_key else task.pixels
        worker.child.conn.send((seq, task.render_key, pixels, task.values, task.image_key, task.frame))
        worker.render, worker.sent[seq] = task.render_key, task

    def answers(self, timeout: float | None, also: Sequence[int] = ()) -> list[tuple[int, Applied | BaseException]]:
        """Wait up to ``timeout`` seconds (None: no limit) for a worker's answer or for one of
        the file descriptors ``also`` to be readable; the answers that came, as (sequence
        number, image or the exception that making it raised).

        Raises:
            RenderError: a worker died with an image unanswered (killed, out of memory?).
        """
        conns = {w.child.conn: w for w in self.workers}
        out: list[tuple[int, Applied | BaseException]] = []
        for ready in wait([*conns, *also], timeout):
            worker = conns.get(ready)  # type: ignore[call-overload]
            if worker is None:
                continue
            while worker in self.workers and worker.child.conn.poll():
                try:
                    answer = worker.child.conn.recv()
                except (EOFError, OSError):
                    self._lost(worker)
                    break
                if answer[0] == "ready":
                    worker.ready = True
                elif answer[0] == "broken":  # the controls did not load there: this process applies them
                    self._retire(worker)
                else:
                    _, seq, result = answer
                    worker.sent.pop(seq, None)
                    out.append((seq, result))
        return out

    def _lost(self, worker: _Worker) -> None:
        worker.child.join(1)
        code = worker.child.exitcode
        sent = dict(worker.sent)
        self._retire(worker)
        if sent:
            task = sent[min(sent)]
            raise RenderError(f"a post-processing worker died ({death_cause(code)}) while making image "
                              f"{task.image_key[:12]} of render {task.render_key[:12]}; what finished is stored: "
                              "run again to resume")

    def _retire(self, worker: _Worker) -> None:
        self.workers.remove(worker)
        worker.child.kill()
        worker.child.join(5)
        worker.child.conn.close()

    def close(self, graceful: bool = True) -> None:
        """End every worker: asked to exit and given :data:`GRACE` seconds when ``graceful``,
        else killed at once."""
        for worker in self.workers:
            if graceful:
                try:
                    worker.child.conn.send(None)
                except OSError:
                    pass  # it has gone already
        for worker in self.workers:
            if graceful:
                worker.child.end(GRACE)
            else:
                worker.child.kill()
                worker.child.join(5)
            worker.child.conn.close()
        self.workers = []


def serve(conn: Connection, blob: bytes, encode: bool) -> None:
    """In a worker: load the post controls, say it is ready, then make each image sent until
    ``None`` comes, answering ``("done", seq, Applied)``, or ``("done", seq, exception)`` when
    making it raised (a user control's :class:`~sweep3d.core.PluginError`, one line naming it)."""
    try:
        post = pickle.loads(blob)
    except Exception as exc:  # noqa: BLE001  (a module the run's process found and this one does not)
        conn.send(("broken", f"{type(exc).__name__}: {exc}"))
        return
    apply = Applier(post, encode)
    widen(conn)
    conn.send(("ready",))
    while (task := conn.recv()) is not None:
        seq, *args = task
        try:
            answer: Applied | BaseException = apply(*args)
        except Exception as exc:  # noqa: BLE001  (raised again in the run's process, in its turn)
            answer = _sendable(exc)
        conn.send(("done", seq, answer))


def widen(conn: Connection) -> None:
    """Let ``conn`` hold :data:`PIPE_BYTES` unread (as far as the system allows), so that a worker
    goes on to its next image instead of waiting for this process to read its last answer."""
    try:
        sock = socket.fromfd(conn.fileno(), socket.AF_UNIX, socket.SOCK_STREAM)  # a duplicate: closed below
    except OSError:
        return
    with sock:
        for option in (socket.SO_SNDBUF, socket.SO_RCVBUF):
            try:
                sock.setsockopt(socket.SOL_SOCKET, option, PIPE_BYTES)
            except OSError:
                pass  # the system's limit stands


def _sendable(exc: Exception) -> BaseException:
    """``exc`` as it can travel to the run's process: itself when it pickles (a sweep3d bug gets
    this process's traceback as a note), else a RuntimeError saying what it was."""
    if not isinstance(exc, UserError):
        exc.add_note("in a post-processing worker:\n" + "".join(traceback.format_exception(exc)))
    try:
        pickle.loads(pickle.dumps(exc))
    except Exception:  # noqa: BLE001  (an exception whose __init__ takes other arguments than its args)
        return RuntimeError(f"{type(exc).__name__}: {exc}\n" + "".join(traceback.format_exception(exc)))
    return exc
