"""The store's writer lock: one process writes, readers never wait."""

from __future__ import annotations

import fcntl
import os
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from sweep3d.cache.files import store_error
from sweep3d.core import StoreBusyError

#: Stores whose writer lock this process holds (by real path), and the thread that took it: only
#: their holder quarantines, and that thread may take the lock again within (see :meth:`WriterLock.lock`).
_HELD: dict[str, int] = {}


class WriterLock:
    """:class:`~sweep3d.cache.store.Store`'s writer lock."""

    root: Path
    ensure_writable: Callable[[], None]  # the store's
    forget_states: Callable[[], None]

    @property
    def holds_lock(self) -> bool:
        """Whether this process holds the store's writer lock (through any store object)."""
        return os.path.realpath(self.root) in _HELD

    @contextmanager
    def lock(self, wait: float = 0.0) -> Iterator[None]:
        """Hold the store's writer lock; readers never take it.

        A command that writes takes it before it computes anything, and holds it to its end; a run
        it starts within (a follow-up that renders fresh jobs) takes it again in the same thread,
        which holds it already: that is a no-op. Another thread of this process is
        refused as another process is.

        Raises:
            StoreBusyError: if another process or thread holds it for longer than ``wait`` seconds.
            StoreWriteError: the lock file cannot be opened (its permissions, a folder in its place).
        """
        held = os.path.realpath(self.root)
        if _HELD.get(held) == threading.get_ident():  # within the same thread's hold: already this caller's
            try:
                yield
            finally:
                self.forget_states()
            return
        self.ensure_writable()
        path = self.root / "lock"
        try:
            fh = open(path, "a+")
        except OSError as exc:
            raise store_error(exc, "write") from None
        deadline = time.monotonic() + wait
        try:
            while True:
                try:
                    fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if time.monotonic() >= deadline:
                        fh.seek(0)
                        holder = fh.read().strip() or "another process"
                        raise StoreBusyError(
                            f"store {self.root} is in use by {holder}; wait for it to finish or pass --wait SECONDS"
                        ) from None
                    time.sleep(0.2)
            fh.seek(0)
            fh.truncate()
            fh.write(f"sweep3d pid {os.getpid()}")
            fh.flush()
            _HELD[held] = threading.get_ident()
            try:
                yield
            finally:
                _HELD.pop(held, None)
                self.forget_states()  # taken under this lock: not to be trusted after it
        finally:
            fh.close()
