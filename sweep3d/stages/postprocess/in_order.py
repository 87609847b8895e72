"""Post-processed images in plan order, made on every core once that pays.

The stage's jobs come as their renders land (a :class:`~sweep3d.driver.Feed`, read here by a
thread of its own so that waiting for a render never stops answers coming back). The first
images are made in this process; once the images waiting would take more than
:data:`START_SECONDS` here (a few renders' images behind: the post controls cost more than the
renders do), worker processes start (:mod:`.post_workers`), and until they are ready this process
goes on making images. Each image is handed on in the order its job came, as soon as it and those
before it are made, so inference takes them as fast as they are made. Where an image is made
changes none of its bytes.
"""

from __future__ import annotations

import os
import queue
import threading
from collections import deque
from dataclasses import dataclass
from multiprocessing.connection import wait
from typing import Any, Iterable, Iterator, Sequence

from sweep3d.spec import ControlInstance
from sweep3d.stages.postprocess.post_workers import Applied, Applier, PostWorkers, Task, shippable

#: Seconds of images waiting (at this process's pace) past which worker processes start: about
#: what starting them costs (a fresh interpreter importing numpy and sweep3d: 0.4–0.5 s of CPU
#: each, benchmarks/RESULTS.md), so a run whose post-processing keeps up with its renders (the
#: quickstart's blur) starts none.
START_SECONDS = 1.0
#: Items read ahead of the one being handed on (their renders decoded): bounds what waits in memory.
AHEAD = 512
#: Images in progress or made but not yet handed on, per worker (answers come out of order).
WINDOW_PER_WORKER = 16


def worker_count(setting: int) -> int:
    """The worker processes ``[postprocess] workers`` asks for: 0 is one per core."""
    return setting or os.cpu_count() or 1


@dataclass
class _Slot:
    """One item in plan order: passed through as it is, or a task and, once made, its image."""

    item: Any
    task: Task | None = None
    sent: bool = False
    made: Applied | BaseException | None = None

    @property
    def done(self) -> bool:
        return self.task is None or self.made is not None


class _Reader:
    """Reads the stage's items in a thread of its own into a bounded queue, waking the consumer
    through a pipe (which it can wait on together with the workers' pipes)."""

    def __init__(self, items: Iterable[Any]) -> None:
        self.queue: queue.Queue = queue.Queue(maxsize=AHEAD)
        self.wake, self._signal = os.pipe()
        os.set_blocking(self.wake, False)
        os.set_blocking(self._signal, False)  # a full pipe already wakes the consumer
        self._stop = threading.Event()
        self._closing = threading.Lock()  # the pipe is never written once closed (its number may be reused)
        self.ended = False  # the consumer has taken the end (or the error)
        self._thread = threading.Thread(target=self._read, args=(iter(items),), name="sweep3d-post-read", daemon=True)
        self._thread.start()

    def _read(self, items: Iterator[Any]) -> None:
        try:
            for item in items:
                if not self._put(("item", item)):
                    return
        except BaseException as exc:  # noqa: BLE001  (the feed's Cancelled, a bug: raised by the consumer)
            self._put(("error", exc))
            return
        self._put(("end", None))

    def _put(self, entry: tuple[str, Any]) -> bool:
        while not self._stop.is_set():
            try:
                self.queue.put(entry, timeout=0.25)
            except queue.Full:
                continue
            with self._closing:
                if not self._stop.is_set():
                    try:
                        os.write(self._signal, b"x")
                    except BlockingIOError:
                        pass
            return True
        return False

    def take(self) -> tuple[str, Any] | None:
        """The next entry read, or None when none is there yet."""
        try:
            return self.queue.get_nowait()
        except queue.Empty:
            return None

    def waiting(self) -> int:
        return self.queue.qsize()

    def drain_wake(self) -> None:
        try:
            while os.read(self.wake, 4096):
                pass
        except BlockingIOError:
            pass

    def close(self) -> None:
        with self._closing:
            self._stop.set()
            os.close(self.wake)
            os.close(self._signal)
        self._thread.join(0.5)  # it may wait on the feed until the pass cancels it: it is a daemon


class InOrder:
    """The items of ``items`` in their order, each :class:`Task` as ``(task, Applied)`` once made
    (in this process or a worker's), anything else as it came. An exception a task raised is
    raised in its turn; one raised reading ``items`` (the feed cancelled) at once.

    Args:
        workers: the most worker processes to start (1: none, everything is made here).
        encode: make each image's PNG too (the run stores its images).
        start_seconds: :data:`START_SECONDS` unless given; 0: start the workers with the first image and make
            every image there (none here while they start), as the tests need.
    """

    def __init__(self, items: Iterable[Any], post: Sequence[ControlInstance], workers: int, encode: bool,
                 start_seconds: float | None = None) -> None:
        self.items, self.post, self.encode = items, list(post), encode
        self.count = workers
        self.start_seconds = START_SECONDS if start_seconds is None else start_seconds
        self.local = Applier(post, encode)
        self.pool: PostWorkers | None = None
        self.started = False  # workers were started (once per pass, whatever became of them)
        self.made_here: list[float] = []  # seconds of each image made in this process
        self.pids: set[int] = set()  # the processes that made the images handed on
        self._sent: dict[int, _Slot] = {}  # sequence number -> slot, for the workers' answers
        self._unsent: deque[_Slot] = deque()  # the slots whose image nobody makes yet, in order
        self._seq = 0

    def __iter__(self) -> Iterator[Any]:
        reader = _Reader(self.items)
        slots: deque[_Slot] = deque()
        finished = False
        try:
            while True:
                self._take(reader, slots)
                if slots and slots[0].done:
                    while slots and slots[0].done:
                        yield self._out(slots.popleft())
                    continue  # take what was read meanwhile before waiting (its wake-up may be spent)
                if not slots and reader.ended:
                    finished = True
                    return
                if self.pool is not None:
                    self._send()
                head = slots[0] if slots else None
                if head is None or head.sent:  # its image is being made: wait for it (or for more items)
                    self._answers(reader, None)
                    continue
                if self.start_seconds == 0:
                    self._maybe_start(reader)
                if self.pool is not None and self.pool.live and self.start_seconds == 0:
                    self._answers(reader, None)  # the workers are starting: they make it
                    continue
                assert self._unsent[0] is head
                head.made = self._here(self._unsent.popleft().task)  # no worker ready (yet): made here meanwhile
                self._maybe_start(reader)
                self._answers(reader, 0)
        finally:
            if self.pool is not None:
                self.pool.close(graceful=finished)
            reader.close()

    def _take(self, reader: _Reader, slots: deque[_Slot]) -> None:
        """Move what the reader has read into ``slots`` (up to the window); raise its error."""
        window = WINDOW_PER_WORKER * max(1, len(self.pool.workers) if self.pool else 1) + 16
        while not reader.ended and len(slots) < window:
            entry = reader.take()
            if entry is None:
                return
            kind, value = entry
            if kind == "error":
                reader.ended = True
                raise value
            if kind == "end":
                reader.ended = True
                return
            slots.append(_Slot(value, value if isinstance(value, Task) else None))
            if isinstance(value, Task):
                self._unsent.append(slots[-1])

    def _out(self, slot: _Slot) -> Any:
        if slot.task is None:
            return slot.item
        if isinstance(slot.made, BaseException):
            raise slot.made
        assert isinstance(slot.made, Applied)
        self.pids.add(slot.made.pid)
        return slot.task, slot.made

    def _here(self, task: Task | None) -> Applied | BaseException:
        assert task is not None
        try:
            made = self.local.task(task)
        except Exception as exc:  # noqa: BLE001  (raised in its turn, as a worker's would be)
            return exc
        self.made_here.append(made.seconds)
        return made

    def _send(self) -> None:
        """Give the workers that can take one the next images not yet sent, in order."""
        assert self.pool is not None
        while self._unsent and self.pool.idle():
            slot = self._unsent.popleft()
            assert slot.task is not None
            self._seq += 1
            self.pool.send(self._seq, slot.task)
            self._sent[self._seq] = slot
            slot.sent = True

    def _answers(self, reader: _Reader, timeout: float | None) -> None:
        """Wait up to ``timeout`` seconds (None: until something comes) for workers' answers or
        more items; record the answers."""
        also = [] if reader.ended else [reader.wake]
        if self.pool is None or not self.pool.live:
            if also and timeout != 0:
                wait(also, timeout)
        else:
            for seq, made in self.pool.answers(timeout, also):
                self._sent.pop(seq).made = made
        reader.drain_wake()

    def _maybe_start(self, reader: _Reader) -> None:
        """Start the workers when the images waiting would take more than :attr:`start_seconds` here."""
        if self.started or self.count <= 1:
            return
        waiting = reader.waiting() + len(self._unsent)
        if self.start_seconds > 0:
            if len(self.made_here) < 2:
                return
            timed = self.made_here[1:]  # the first image pays imports (scipy's, the corruptions')
            if waiting * sum(timed) / len(timed) <= self.start_seconds:
                return
        self.started = True
        blob = shippable(self.post)
        if blob is not None and waiting:
            self.pool = PostWorkers(blob, min(self.count, waiting), self.encode)
