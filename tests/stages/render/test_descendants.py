"""A render worker's descendants end with it, also those that left its process group (issue 45,
item 2): a process started in a session of its own (``start_new_session=True``, ``setsid``), and
one whose parent exited (a daemon's double fork), which the worker adopts. Each test marks its
processes with a ``sleep`` argument of its own and looks for them in ``/proc`` afterwards."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from multiprocessing.connection import Connection

import pytest

from sweep3d.stages.render.descendants import descendants, end_descendants
from tests.helpers.processes import marker, running

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and prctl are Linux's")


def escape(mark: str) -> None:
    """Start ``sleep`` three ways out of this process's group: a new session, ``setsid``, and a
    daemon's double fork (its parent exits at once: it is re-parented to the nearest subreaper)."""
    subprocess.Popen(["sleep", mark], start_new_session=True)
    subprocess.Popen(["setsid", "sleep", mark])
    subprocess.run(["sh", "-c", f"setsid sleep {mark} >/dev/null 2>&1 &"], check=True)


def _wait_for(mark: str, n: int) -> list[int]:
    deadline = time.monotonic() + 10
    while len(running(mark)) < n and time.monotonic() < deadline:
        time.sleep(0.05)
    return running(mark)


def _kill(pids: list[int]) -> None:
    for pid in pids:  # a failing test leaves no orphan either
        try:
            os.kill(pid, 9)
        except ProcessLookupError:
            pass


def test_end_descendants_ends_what_left_the_group_and_spares_the_group() -> None:
    """Below a shell: a sleep in its group (spared) and one in a session of its own (ended)."""
    mark, kept = marker(), marker()
    shell = subprocess.Popen(["sh", "-c", f"setsid sleep {mark} & sleep {kept}"], process_group=0)
    try:
        assert len(_wait_for(mark, 1)) == 1 and len(_wait_for(kept, 1)) == 1
        assert {pid for pid, _ in descendants(shell.pid)} >= set(running(mark))
        assert end_descendants(shell.pid, spare_group=shell.pid) == 1
        assert not running(mark) and running(kept) and shell.poll() is None
    finally:
        _kill(running(mark) + running(kept))
        shell.kill()
        shell.wait()


def _escape_then(conn: Connection, mark: str, stay: bool) -> None:
    """In a :class:`Child`: start the escapees, say so, then exit when told, or wait to be killed (``stay``)."""
    escape(mark)
    conn.send("started")
    if stay:
        time.sleep(600)
    conn.recv()


@pytest.mark.blender  # a Child (a fresh interpreter), which the fast lane refuses; no Blender is imported
@pytest.mark.parametrize("ended", ["exits", "killed"])
def test_what_a_child_started_in_a_session_of_its_own_ends_with_it(ended: str) -> None:
    from sweep3d.stages.render.child import Child

    mark = marker()
    child = Child(_escape_then, (mark, ended == "killed"), "sweep3d-test")
    try:
        assert child.conn.recv() == "started"
        assert len(_wait_for(mark, 3)) == 3, "three sleeps, each out of the child's group"
        if ended == "killed":
            child.kill()
        else:
            child.conn.send("exit")
        child.join(10)
        assert child.exitcode is not None
        assert not running(mark), f"outlived the child: {running(mark)}"
    finally:
        _kill(running(mark))
        child.kill()
        child.join(5)
