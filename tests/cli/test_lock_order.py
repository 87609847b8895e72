"""Which commands share a store with a running one (docs/concepts/cache.md, "Commands side by
side"): a command that writes takes the store's lock before it computes anything and holds it to
its end, waiting for it with ``--wait``; one started beside another command's hold is refused (or
waits) at once, its work never thrown away. ``stability`` and ``realism score`` computed first and
were refused at the end; the busy line told ``stability`` and ``confirm`` to pass a ``--wait``
they did not have (issue 45, item 9)."""

from __future__ import annotations

import os
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.core import UserError
from tests.helpers import build_store, one_line, store_tree

#: Each writer, and what it computes once it holds the lock (made to fail loudly if reached).
WRITERS = [
    (["stability", "SPEC"], "sweep3d.followups.stability.check._check_model"),
    (["confirm", "SPEC"], "sweep3d.followups.confirm.run._confirmed"),
    (["sheet", "SPEC"], "sweep3d.runner.runner.run_stages"),  # the runner runs its stages
    (["cache", "verify", "SPEC", "--repair"], "sweep3d.cache.verify"),
]


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory) -> Path:
    """A spec and its store of synthetic results (no Blender, no model)."""
    return build_store(tmp_path_factory.mktemp("locks") / "run", 24, images=False)


@contextmanager
def held(root: Path, seconds: float = 60.0) -> Iterator[None]:
    """The store's lock held by another command: a thread of this process, refused as another
    process is, that lets go after ``seconds``."""
    ready = threading.Event()
    release = threading.Event()

    def hold() -> None:
        with Store(root).lock():
            ready.set()
            release.wait(seconds)

    holder = threading.Thread(target=hold)
    holder.start()
    assert ready.wait(30)
    try:
        yield
    finally:
        release.set()
        holder.join()


def data(root: Path) -> dict[str, tuple[int, int]]:
    """The store's files but its lock file (which the holder writes)."""
    return {name: state for name, state in store_tree(root).items() if name != "lock"}


def invoke(spec: Path, command: list[str]):
    return CliRunner().invoke(app, [str(spec) if a == "SPEC" else a for a in command])


@pytest.mark.parametrize("command, computes", WRITERS, ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_a_writer_beside_another_s_hold_is_refused_before_it_computes(synthetic: Path, monkeypatch, command: list[str],
                                                                        computes: str) -> None:
    def reached(*args, **kwargs):
        raise AssertionError(f"{computes} ran without the store's lock")

    monkeypatch.setattr(computes, reached)
    root = synthetic.parent / "store"
    before = data(root)
    with held(root):
        started = time.monotonic()
        result = invoke(synthetic, command)
    assert result.exit_code == 2, result.output
    assert one_line(result.output) == (f"error: store {root} is in use by sweep3d pid {os.getpid()}; wait for it to "
                                       "finish or pass --wait SECONDS")
    assert time.monotonic() - started < 20 and data(root) == before


@pytest.mark.parametrize("command, computes", WRITERS, ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_with_wait_a_writer_waits_for_the_hold_then_computes(synthetic: Path, monkeypatch, command: list[str],
                                                              computes: str) -> None:
    """Every command the busy line names takes ``--wait``: it waits, then holds the lock itself."""
    root = synthetic.parent / "store"

    def reached(*args, **kwargs):
        assert Store(root).holds_lock
        raise UserError("reached with the lock")

    monkeypatch.setattr(computes, reached)
    with held(root, seconds=1.0):
        result = invoke(synthetic, [*command, "--wait", "60"])
    assert result.exit_code == 2 and one_line(result.output) == "error: reached with the lock", result.output


def test_a_command_holding_the_lock_runs_what_takes_it_again_in_its_thread(tmp_path: Path) -> None:
    """``confirm`` and ``realism score --engine`` run a run within their hold: the same thread
    taking the lock again is a no-op; it stays held until the outer hold ends."""
    root = tmp_path / "store"
    with Store(root).lock():
        with Store(root).lock():
            assert Store(root).holds_lock
        assert Store(root).holds_lock
    assert not Store(root).holds_lock
    with held(root, seconds=30.0):
        with pytest.raises(UserError, match="is in use by"):
            with Store(root).lock():
                pass
