"""The listing and file states of a store's blobs, taken by a child process while the run plans.

A rerun checks each cached blob's file state against the memo of verified blobs
(:func:`sweep3d.cache.blobs.damaged_blobs`): one ``stat`` per blob, about 3 s of one core at
10⁶ blobs. The states do not depend on the plan, so a run holding the lock starts a child
(:mod:`.stat_blobs`, standard library only) that takes them all while the parent plans on the
other core, and :func:`~sweep3d.cache.blobs.file_states` reads them from it. The child lists every
blob folder to do so, and that listing serves the run's other looks at the folders as well: which
blobs exist (:meth:`Store.existing_blobs`) and which temp files killed writers left
(:func:`~sweep3d.cache.garbage.remove_killed_writers_temp_files`), so the parent lists none.
A run whose plan is small (:data:`MIN_JOBS`) stops the child once it has planned: it would wait
for a look at every blob of a large store to check a few of them.

A snapshot is right only while nothing writes a blob: a run takes it as soon as it holds the
lock (what killed runs left are temp files, not blobs: removing them changes no blob) and
forgets it (:meth:`Store.forget_states`) once its first pass has found what is cached, before
anything is computed. A key the snapshot lacks is stat'ed directly, and a child
that fails or hangs costs only the time waited: the states are then taken as before.

The work is shared by up to :data:`CHILDREN` children, each a run of the folders in name order.
Each sends the digest of its blobs' keys and states and the folders' other names first
(:meth:`StateSnapshot.head`: what a run whose outcomes are recorded needs, see
``sweep3d.runner.settled``), and the states and keys themselves after, read only by a run that
looks key by key (:meth:`StateSnapshot.read`).
"""

from __future__ import annotations

import hashlib
import os
import select
import subprocess
import sys
import time
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from sweep3d.cache import stat_blobs
from sweep3d.cache.key_join import positions

MIN_BLOBS = 20_000  # below this many blob files, a child (~30 ms to start) wins nothing
MIN_JOBS = 20_000  # a plan of fewer jobs checks too few blobs for the child's look at every blob to pay
WAIT = 120.0  # seconds to wait for the children before stat'ing in-process
CHILDREN = 2  # at most this many children share the blob folders


@dataclass(frozen=True)
class Taken:
    """What the children found: every blob's key (in key order) and file state, and each blob
    folder's other names (a killed writer's temp file, a pass's blob)."""

    texts: tuple[str, ...]  # each child's keys, NUL between two (split when first asked for)
    states: np.ndarray
    others: dict[str, list[str]]
    digest: str = ""  # SHA-256 of every blob's key and state as the children wrote them (not the others)

    @cached_property
    def keys(self) -> pa.Array:
        """Every blob's key, in key order (a run that finds its outcomes recorded never asks)."""
        sep = stat_blobs.SEPARATOR
        parts = [pc.split_pattern(pa.array([text]), sep).flatten() for text in self.texts if text]
        return pa.concat_arrays(parts) if parts else pa.array([], type=pa.string())

    @cached_property
    def key_set(self) -> frozenset[str]:
        """:attr:`keys` as a set, for existence checks."""
        return frozenset(self.keys.to_pylist())


@dataclass(frozen=True)
class Head:
    """What a child says first: how many blobs and how long their keys' text, the digest of
    their states and keys, and the blob folders' other names (``<folder>/<name>``)."""

    n: int
    length: int
    digest: str
    others: dict[str, list[str]]


class StateSnapshot:
    """The children listing and stat'ing every blob under ``blobs`` (a store's blob folder): one
    per :data:`CHILDREN` share of the folders, as the machine has cores (the ``stat`` calls are
    mostly the kernel's time, and a machine of two cores has one to spare while the parent plans).
    Each says its digest and other names first (:meth:`head`); the states and keys, 100 MB at
    10⁶ blobs, are read only by a run that looks key by key (:meth:`read`)."""

    def __init__(self, blobs: Path) -> None:
        parts = max(1, min(CHILDREN, os.cpu_count() or 1))
        self.processes: list[subprocess.Popen] = [subprocess.Popen(
            [sys.executable, stat_blobs.__file__, str(blobs), str(part), str(parts)],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL) for part in range(parts)]
        self.heads: list[Head] | None = None  # once read
        self.taken: Taken | None = None  # once read
        self.failed = False

    def states(self, keys: pa.Array) -> tuple[np.ndarray, np.ndarray] | None:
        """(the states of ``keys`` in their order, whether the snapshot has each one), waiting for
        the children; None when one failed."""
        taken = self.read()
        if taken is None:
            return None
        where = positions(keys, taken.keys)  # both in key order: a binary search (none for the very same keys)
        found = where >= 0
        return taken.states[np.where(found, where, 0)], found

    def head(self) -> tuple[str, dict[str, list[str]]] | None:
        """(the digest of every blob's key and state, each blob folder's other names), waiting for
        the children to have stat'ed every blob; None when one failed or hung."""
        heads = self._heads()
        if heads is None:
            return None
        digest = heads[0].digest if len(heads) == 1 else \
            hashlib.sha256("".join(h.digest for h in heads).encode()).hexdigest()
        return digest, {folder: names for h in heads for folder, names in h.others.items()}

    def read(self) -> Taken | None:
        """What the children found, waiting for them; None when one failed or hung."""
        if self.taken is not None or self.failed:
            return self.taken
        looked = self.head()
        heads = self.heads
        if looked is None or heads is None:
            return None
        texts, states = [], []
        deadline = time.monotonic() + WAIT  # the children have stat'ed every blob: they only write now
        for process, head in zip(self.processes, heads):
            bulk = _read_exact(process, 32 * head.n + head.length, deadline)
            if bulk is None:
                return self._fail()
            states.append(np.frombuffer(bulk, dtype=np.int64, count=4 * head.n).reshape(head.n, 4))
            try:
                texts.append(bulk[32 * head.n:].decode())
            except UnicodeDecodeError:  # a blob's name that is not UTF-8: the parent looks for itself
                return self._fail()
            if (texts[-1].count(stat_blobs.SEPARATOR) + 1 if head.n else 0) != head.n:
                return self._fail()
        _stop(self.processes)
        self.taken = Taken(tuple(texts), np.concatenate(states), looked[1], looked[0])
        return self.taken

    def close(self) -> None:
        """Stop the children if they still run (their answer is not needed)."""
        _stop(self.processes)

    def _heads(self) -> list[Head] | None:
        if self.heads is None and not self.failed:
            deadline = time.monotonic() + WAIT  # counted from the first look, as planning may take long
            heads = [_read_head(process, deadline) for process in self.processes]
            if None in heads:
                self._fail()
                return None
            self.heads = heads  # type: ignore[assignment]
        return self.heads

    def _fail(self) -> None:
        self.failed = True
        _stop(self.processes)


def _read_head(process: subprocess.Popen, deadline: float) -> Head | None:
    """A child's :class:`Head`; None when it failed, hung or wrote something else."""
    sizes = _read_exact(process, 56, deadline)
    if sizes is None:
        return None
    n, length, rest = (int.from_bytes(sizes[i:i + 8], "little") for i in (0, 8, 16))
    names = _read_exact(process, rest, deadline)
    if names is None:
        return None
    others: dict[str, list[str]] = {}
    text = names.decode("utf-8", "surrogateescape")  # as os.listdir would name them
    for entry in text.split(stat_blobs.SEPARATOR) if text else ():
        folder, _, name = entry.partition("/")
        others.setdefault(folder, []).append(name)
    return Head(n, length, sizes[24:56].hex(), others)


def _read_exact(process: subprocess.Popen, size: int, deadline: float) -> bytes | None:
    """``size`` bytes of the child's output, waiting until ``deadline``; None when it ends first."""
    fd = process.stdout.fileno()  # type: ignore[union-attr]
    chunks, left = [], size
    while left:
        ready, _, _ = select.select([fd], [], [], max(0.0, deadline - time.monotonic()))
        if not ready:
            return None
        chunk = os.read(fd, min(left, 1 << 20))
        if not chunk:
            return None
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def _stop(processes: list[subprocess.Popen]) -> None:
    """Kill the children still running and reap each one."""
    for process in processes:
        if process.poll() is None:
            process.kill()
        process.wait()
        if process.stdout is not None:
            process.stdout.close()
