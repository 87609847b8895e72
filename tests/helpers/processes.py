"""Finding a test's processes in ``/proc`` by a mark of their own: a ``sleep`` argument no other
process has, so a test can tell that what it started is gone (Linux)."""

from __future__ import annotations

import os
import uuid


def marker() -> str:
    """A ``sleep`` argument no other process has: 9997 seconds and a unique fraction."""
    return f"9997.{uuid.uuid4().int % 10**9:09d}"


def running(mark: str) -> list[int]:
    """The live processes with ``mark`` as an argument (zombies left out)."""
    found = []
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/cmdline", "rb") as fh:
                argv = fh.read().split(b"\0")
            with open(f"/proc/{name}/stat", "rb") as fh:
                state = fh.read().rsplit(b")", 1)[1].split()[0]
        except OSError:  # gone meanwhile
            continue
        if mark.encode() in argv and state not in (b"Z", b"X"):
            found.append(int(name))
    return found
