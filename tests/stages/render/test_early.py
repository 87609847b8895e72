"""The render worker ``sweep3d run`` starts before it reads the spec (``stages.render.early``)."""

from __future__ import annotations

import sys
from multiprocessing.connection import Connection

import pytest

from sweep3d.stages.render import early
from sweep3d.stages.render.child import Child


def _report(conn: Connection) -> None:
    """In the child: what it imported ahead, and its sys.path."""
    conn.send(("colorsys" in sys.modules, "wave" in sys.modules, list(sys.path)))


def test_a_child_started_ahead_imports_first_then_runs_its_work_with_the_parents_newer_path(tmp_path) -> None:
    child = Child(None, name="sweep3d-test", preload=("no_such_module", "colorsys", "os:getpid"))
    try:
        sys.path.append(str(tmp_path))  # a spec read meanwhile put its folder there
        try:
            child.assign(_report, ())
        finally:
            sys.path.remove(str(tmp_path))
        ahead, not_asked, path = child.conn.recv()
        assert ahead and not not_asked  # imported ahead, past a module that does not exist
        assert path[-1] == str(tmp_path)
    finally:
        child.end()
    assert child.exitcode == 0


@pytest.fixture
def started(monkeypatch):
    """``early.start`` with nothing to import ahead (no Blender: the protocol is under test)."""
    monkeypatch.setattr(early, "PRELOAD", ())
    early.start()
    yield early._waiting
    early.drop()


@pytest.mark.parametrize(("engine", "device"), [("mitsuba", "cpu"), ("cycles", "cuda")])
def test_a_worker_started_ahead_that_does_not_fit_is_ended(started, engine: str, device: str) -> None:
    assert started is not None and started.is_alive()
    assert early.take(engine, device) is None
    assert started.exitcode is not None
    assert early.take("cycles", "cpu") is None  # taken once


def test_a_fitting_worker_is_taken_once_and_one_left_is_ended(started) -> None:
    early.start()
    assert early._waiting is started  # a second start keeps the first
    taken = early.take("cycles", "cpu")
    assert taken is started and taken.is_alive()
    assert early.take("cycles", "cpu") is None
    taken.end(grace=0)
    early.start()
    left = early._waiting
    early.drop()
    assert left.exitcode is not None and early._waiting is None


def test_on_one_core_nothing_is_started_ahead(monkeypatch) -> None:
    monkeypatch.setattr(early, "_usable_cores", lambda: 1)
    early.start()
    assert early._waiting is None
    assert early.take("cycles", "cpu") is None
