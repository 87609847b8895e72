"""Running test code as an unprivileged user: root reads every file whatever its permissions,
so a test of a file the user may not read runs its call in a forked child that drops root's
privileges first (:func:`as_user`), on files handed over to that user (:func:`hand_over`)."""

from __future__ import annotations

import os
import pickle
import time
from pathlib import Path
from typing import Callable, TypeVar

import pytest

T = TypeVar("T")
NOBODY = "nobody"


def hand_over(folder: Path) -> None:
    """Give ``folder`` and everything in it to the user of :func:`as_user` (when this is root)."""
    if os.geteuid() == 0:
        owner = _user()
        for path in [folder.parent, folder, *folder.rglob("*")]:
            os.chown(path, owner.pw_uid, owner.pw_gid, follow_symlinks=False)


def _user():
    """The unprivileged user the permission tests run as (they skip where there is none)."""
    import pwd

    try:
        return pwd.getpwnam(NOBODY)
    except KeyError:
        pytest.skip(f"no user {NOBODY!r} to drop privileges to")


def as_user(call: Callable[[], T]) -> T:
    """``call()`` as an unprivileged user: in a forked child that drops root's privileges first
    (root ignores permissions), or here when this process has none to drop. Skips the test
    where they cannot be dropped."""
    if os.geteuid() != 0:
        return call()
    owner = _user()
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        try:
            os.close(read)
            result = _dropped(owner, call)
            with os.fdopen(write, "wb") as fh:
                pickle.dump(result, fh)
        finally:
            os._exit(0)
    os.close(write)
    data = _answer(read, pid)
    if data is None:  # the child waits on a lock a thread of this process held when it forked
        pytest.skip(f"the forked child hung for {CHILD_TIMEOUT:.0f} s on a lock this process's threads held at the "
                    "fork (the session's Chromium, DuckDB or torch pools): a limit of forking a threaded test run")
    result = pickle.loads(data) if data else "the child died"
    if isinstance(result, str) and result.startswith("skip: "):
        pytest.skip(result.removeprefix("skip: "))
    assert not (isinstance(result, str) and result.startswith("the child")), result
    return result


#: Seconds a child of :func:`as_user` may take (each runs a few commands on a small store).
CHILD_TIMEOUT = 180.0


def _answer(read: int, pid: int) -> bytes | None:
    """What the child wrote before it exited; None if it hung (it is killed)."""
    import select
    import signal

    chunks, deadline = [], time.monotonic() + CHILD_TIMEOUT
    with os.fdopen(read, "rb", buffering=0) as fh:
        while True:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fh], [], [], left)[0]:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                return None
            chunk = fh.read(1 << 16)
            if not chunk:
                break
            chunks.append(chunk)
    os.waitpid(pid, 0)
    return b"".join(chunks)


def _dropped(owner, call: Callable[[], T]) -> T | str:
    """In the forked child: ``call()`` once it runs as ``owner``, or why it could not."""
    try:
        os.setgroups([])
        os.setgid(owner.pw_gid)
        os.setuid(owner.pw_uid)
    except OSError as exc:
        return f"skip: cannot drop root's privileges here ({exc})"
    checkout = Path(__file__).resolve().parents[2]
    if not os.access(checkout, os.R_OK | os.X_OK):  # a clone in a private folder (mktemp's 0700)
        return f"skip: the checkout {checkout} is private: {NOBODY!r} cannot read the code it would run"
    try:
        return call()
    except BaseException as exc:  # noqa: BLE001  (reported to the parent, which fails the test)
        return f"the child failed: {type(exc).__name__}: {exc}"
