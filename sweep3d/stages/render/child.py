"""Child processes of a run (render workers, Blender helpers) that never run the user's script
and never outlive their run.

multiprocessing's ``spawn`` runs the parent's ``__main__`` again in every child (as
``__mp_main__``), so that what was defined there can be unpickled: a user's script without
``if __name__ == "__main__":`` would run its whole body again in each render worker (taking the
store's lock its parent holds), and a script read from standard input (``<stdin>``) cannot be
found at all. sweep3d's children need nothing of ``__main__`` (a rendered control defined there
is refused at load), so each is a plain ``python -c`` that imports only what it is sent: the
parent's ``sys.path``, then a function by name and its arguments, over one pipe.

Each child leads its own process group, in its run's session: whatever it starts (a scene edit
that forks, multiprocessing's resource tracker) is in that group, and goes when the child is
ended or reaped (:meth:`Child.join`, :meth:`Child.kill`), and at the latest when its parent
exits. What leaves the group (a process started in a session of its own) is still below the
child in the process tree, which adopts its orphans: the child ends it before it exits, and
:meth:`Child.kill` ends it with the group (:mod:`.descendants`). A child dies with its parent
(:func:`die_with_parent`).
"""

from __future__ import annotations

import atexit
import ctypes
import importlib
import os
import pickle
import signal
import subprocess
import sys
import time
import traceback
from dataclasses import dataclass
from multiprocessing import Pipe
from multiprocessing.connection import Connection, wait
from typing import Any, Callable

from sweep3d.stages.render.descendants import adopt_orphans, end_descendants

PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>
#: What the child runs: no import of sweep3d until the parent's ``sys.path`` is in place.
BOOTSTRAP = ("import sys\nfrom multiprocessing.connection import Connection\n"
             "conn = Connection(int(sys.argv[1]))\nsys.path[:] = conn.recv()\n"
             "from sweep3d.stages.render.child import serve\nserve(conn, int(sys.argv[2]))\n")

_parent_pid: int | None = None  # set in a child: the process it works for
_live: set[Child] = set()  # children not yet reaped, ended when this process exits


class Child:
    """A child process running ``target(conn, *args)`` in a fresh interpreter; ``conn`` is the
    parent's end of their pipe. The surface of ``multiprocessing.Process`` that the pools use
    (``pid``, ``sentinel``, ``is_alive``, ``exitcode``, ``kill``, ``join``), acting on the
    child's whole process group."""

    def __init__(self, target: Callable[..., Any] | None, args: tuple = (), name: str = "sweep3d-child",
                 preload: tuple[str, ...] = ()) -> None:
        """``target`` None: a child started ahead of its work, importing ``preload`` (bpy) while
        the parent goes on; :meth:`assign` gives it the work."""
        self.name = name
        self.conn, theirs = Pipe()
        watch_r, watch_w = os.pipe()  # where pidfd_open is missing: EOF once the child (and what it forked) ends
        try:
            self.popen = subprocess.Popen(
                [sys.executable, *_interpreter_flags(), "-c", BOOTSTRAP, str(theirs.fileno()), str(os.getpid())],
                pass_fds=(theirs.fileno(), watch_w), stdin=subprocess.DEVNULL, process_group=0)
        finally:
            theirs.close()
            os.close(watch_w)
        self.pid = self.popen.pid
        self.sentinel = _pidfd(self.pid, watch_r)  # readable once it exits, before it is reaped
        self._assigned_path = list(sys.path)  # the sys.path the child has
        _live.add(self)
        try:
            self.conn.send(list(sys.path))
            if preload:
                self.conn.send(Preload(preload))
        except (BrokenPipeError, ConnectionResetError):
            pass  # it died at once: its reader sees the closed pipe and the exit code says why
        if target is not None:
            self.assign(target, args)

    def assign(self, target: Callable[..., Any], args: tuple = (), name: str | None = None) -> None:
        """Have the child run ``target(conn, *args)``; a child started ahead is sent this process's
        ``sys.path`` again first (a spec read since may have put its folder there)."""
        self.name = name or self.name
        try:
            if self._assigned_path != sys.path:
                self.conn.send(list(sys.path))
                self._assigned_path = list(sys.path)
            self.conn.send((target, args))
        except (BrokenPipeError, ConnectionResetError):
            pass  # it died at once: its reader sees the closed pipe and the exit code says why
        except BaseException:  # an argument that does not pickle: no child waits for it
            self.kill()
            self.join(5)
            raise

    def __repr__(self) -> str:
        return f"<Child {self.name} pid {self.pid} exitcode {self.exitcode}>"

    @property
    def exitcode(self) -> int | None:
        """Its exit code, or minus the signal that ended it; None while it runs."""
        if self.popen.returncode is not None:
            return self.popen.returncode
        try:  # WNOWAIT: not reaped, so its pid (its group's id) stays its own until join kills the group
            info = os.waitid(os.P_PID, self.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
        except ChildProcessError:  # reaped by someone else's os.wait()
            return self.popen.poll()
        if info is None:
            return None
        return info.si_status if info.si_code == os.CLD_EXITED else -info.si_status

    def is_alive(self) -> bool:
        return self.exitcode is None

    def kill(self) -> None:
        """SIGKILL the child, everything in its process group, and its descendants that left the group."""
        if self.popen.returncode is None:  # else its group's id may be another's by now
            _kill_tree(self.pid)

    def join(self, timeout: float | None = None) -> None:
        """Wait up to ``timeout`` seconds for the child to exit; once it has, end what it left
        running in its group and reap it."""
        if self.popen.returncode is not None:
            return
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.exitcode is None:
            left = 0.1 if deadline is None else min(0.1, deadline - time.monotonic())
            if left <= 0:
                return
            wait([self.sentinel], left)
        _kill_group(self.pid)  # a forked edit's children, a resource tracker: nothing outlives it
        self.popen.wait()
        os.close(self.sentinel)
        _live.discard(self)

    def end(self, grace: float = 5.0) -> None:
        """Let the child exit by itself for ``grace`` seconds, then kill it; either way its whole
        group goes and it is reaped."""
        self.join(grace)
        if self.popen.returncode is None:
            self.kill()
            self.join(5)


def _interpreter_flags() -> list[str]:
    """This interpreter's command-line flags (``-X``, ``-W``, ``-O``…), for the child, as
    multiprocessing passes them."""
    return subprocess._args_from_interpreter_flags()  # noqa: SLF001  (what multiprocessing calls)


def _pidfd(pid: int, fallback: int) -> int:
    """A file descriptor readable once ``pid`` exits (a pidfd), else ``fallback``."""
    try:
        fd = os.pidfd_open(pid)
    except (AttributeError, OSError):  # Linux before 5.3
        return fallback
    os.close(fallback)
    return fd


def _kill_group(pgid: int, sig: int = signal.SIGKILL) -> None:
    try:
        os.killpg(pgid, sig)
    except (ProcessLookupError, PermissionError):
        pass  # nothing left of it


def _kill_tree(pid: int) -> None:
    """SIGKILL the child ``pid`` with its group and every descendant outside it: the group stopped
    first, so that nothing in it starts another process meanwhile."""
    _kill_group(pid, signal.SIGSTOP)
    end_descendants(pid)
    _kill_group(pid)


@atexit.register
def _end_children() -> None:
    """Leave no child behind when this process exits (a pool closes its own; this is the net)."""
    for child in list(_live):
        child.kill()
        child.join(5)


def live_children() -> list[Child]:
    """The children this process started that are not reaped yet."""
    return sorted(_live, key=lambda child: child.pid)


def serve(conn: Connection, parent: int) -> None:
    """In the child: run the target the parent sends, then exit as Python does (Blender's exit
    handler removes its temporary folder), without waiting for what a scene edit started."""
    die_with_parent(parent)
    adopt_orphans()  # what an edit starts in a session of its own stays below this process, to be ended
    signal.signal(signal.SIGTTOU, signal.SIG_IGN)  # its own group is not the terminal's: may still write
    code = 0
    try:
        message = conn.recv()
        while not isinstance(message, tuple):  # a child started ahead: what to import, a newer sys.path
            if isinstance(message, Preload):
                message.load()
            else:
                sys.path[:] = message
            message = conn.recv()
        target, args = message
        target(conn, *args)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    except BaseException:  # noqa: BLE001  (said on stderr, as a spawned process would)
        traceback.print_exc()
        code = 1
    _stop_multiprocessing_children()
    end_descendants(os.getpid(), spare_group=os.getpgid(0))  # what left the group; the parent ends the group
    sys.exit(code)


@dataclass(frozen=True)
class Preload:
    """What a child started ahead imports while it waits for its work (:class:`Child`)."""

    #: modules to import, or ``module:function`` to call (with no arguments) once imported
    names: tuple[str, ...]

    def load(self) -> None:
        """Import each; one that fails is left for the work itself to import, and to say what is
        wrong in its own words."""
        for name in self.names:
            module, _, function = name.partition(":")
            try:
                loaded = importlib.import_module(module)
                if function:
                    getattr(loaded, function)()
            except Exception:  # noqa: BLE001  (see above)
                pass


def _stop_multiprocessing_children() -> None:
    """Kill the processes an edit started with multiprocessing: its exit handler would wait for
    them (the parent kills whatever else is left in this child's group once it has exited)."""
    mp = sys.modules.get("multiprocessing")
    if mp is not None:
        for child in mp.active_children():
            child.kill()
            child.join(1)


def die_with_parent(parent: int) -> None:
    """Make this child die when its parent does, and exit now if the parent has already gone.

    An orphan would render on for minutes and write blobs into a store whose lock it does not
    hold. Linux sends the signal when the parent's *thread* that started the child exits: pools
    are started from the main thread. Elsewhere, :func:`orphaned` before each write is the guard.
    """
    global _parent_pid
    _parent_pid = parent
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if orphaned():  # the parent died before the request: no signal will come
        os._exit(1)


def orphaned() -> bool:
    """Whether this child's parent has died (it was re-parented to init or a subreaper)."""
    return _parent_pid is not None and os.getppid() != _parent_pid


def call_in_child(func: Callable[..., Any], *args: Any, name: str = "sweep3d-blender") -> Any:
    """``func(*args)`` in a fresh child process (one that may import bpy while this one never
    does): its result, or the exception it raised, raised here.

    Raises:
        RenderError: the child died without an answer.
    """
    from sweep3d.core import RenderError
    from sweep3d.stages.render.pool import death_cause

    child = Child(_answer, (func, args), name)
    try:
        ok, value = child.conn.recv()
    except (EOFError, OSError):
        child.end()
        raise RenderError(f"{name} died ({death_cause(child.exitcode)})") from None
    finally:
        child.end()
        child.conn.close()
    if not ok:
        raise value
    return value


def _answer(conn: Connection, func: Callable[..., Any], args: tuple) -> None:
    """In the child: send back ``(True, func(*args))``, or ``(False, the exception)``."""
    try:
        conn.send((True, func(*args)))
    except Exception as exc:  # noqa: BLE001  (raised again in the parent)
        conn.send((False, exc if _pickles(exc) else RuntimeError(f"{type(exc).__name__}: {exc}")))


def _pickles(exc: BaseException) -> bool:
    """Whether ``exc`` survives the trip to the parent (an exception whose ``__init__`` takes
    other arguments than its ``args`` does not unpickle)."""
    try:
        pickle.loads(pickle.dumps(exc))
    except Exception:  # noqa: BLE001
        return False
    return True
