"""The processes descended from one, wherever they went: found by walking ``/proc``, and ended.

A render worker leads a process group, and killing the group ends what a scene edit forks. A
process an edit starts in a session or group of its own (``start_new_session=True``, ``setsid``,
a daemon's double fork) leaves the group, and would outlive the worker, re-parented to init. So
a worker adopts its orphaned descendants (:func:`adopt_orphans`: Linux's child subreaper), which
keeps every one of them below it in the process tree, and the tree is ended whole
(:func:`end_descendants`) when the worker exits or is killed. Linux only (``/proc``, ``prctl``);
elsewhere these do nothing and the process group is the bound.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import time

PR_SET_CHILD_SUBREAPER = 36  # from <linux/prctl.h>
PROC = "/proc"
#: How long :func:`end_descendants` keeps ending what it finds (a process may fork as it is killed).
END_SECONDS = 2.0


def adopt_orphans() -> None:
    """Make this process the parent of its descendants whose own parent exits (a child subreaper),
    so none of them escapes to init; call it before starting any. Nothing outside Linux."""
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)


def _processes() -> dict[int, tuple[int, int, str]]:
    """pid → (parent's pid, process group, state letter) of every process ``/proc`` lists."""
    try:
        names = os.listdir(PROC)
    except OSError:
        return {}
    found = {}
    for name in names:
        if not name.isdigit():
            continue
        try:
            with open(f"{PROC}/{name}/stat", "rb") as fh:
                data = fh.read()
        except OSError:  # gone meanwhile
            continue
        fields = data[data.rfind(b")") + 2:].split()  # after the command's name, which may hold anything
        found[int(name)] = (int(fields[1]), int(fields[2]), fields[0].decode())
    return found


def descendants(pid: int) -> list[tuple[int, int]]:
    """(pid, process group) of each live process below ``pid`` in the process tree (zombies left out)."""
    processes = _processes()
    children: dict[int, list[int]] = {}
    for child, (parent, _, _) in processes.items():
        children.setdefault(parent, []).append(child)
    found, stack = [], [pid]
    while stack:
        for child in children.get(stack.pop(), []):
            stack.append(child)
            if processes[child][2] not in "ZX":
                found.append((child, processes[child][1]))
    return found


def end_descendants(pid: int, spare_group: int | None = None, seconds: float = END_SECONDS) -> int:
    """SIGKILL every process below ``pid`` (but those in ``spare_group``), again until none is left
    or ``seconds`` have passed: one may fork as it is killed. Returns how many were signalled."""
    ended: set[int] = set()
    deadline = time.monotonic() + seconds
    while True:
        left = [p for p, group in descendants(pid) if group != spare_group]
        if not left or time.monotonic() > deadline:
            return len(ended)
        for process in left:
            try:
                os.kill(process, signal.SIGKILL)
                ended.add(process)
            except (ProcessLookupError, PermissionError):
                pass  # gone, or not ours to end
        time.sleep(0.01)
