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
"""

from __future__ import annotations

import hashlib
import os
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


class StateSnapshot:
    """The children listing and stat'ing every blob under ``blobs`` (a store's blob folder): one
    per :data:`CHILDREN` share of the folders, as the machine has cores (the ``stat`` calls are
    mostly the kernel's time, and a machine of two cores has one to spare while the parent plans)."""

    def __init__(self, blobs: Path) -> None:
        parts = max(1, min(CHILDREN, os.cpu_count() or 1))
        self.processes: list[subprocess.Popen] = [subprocess.Popen(
            [sys.executable, stat_blobs.__file__, str(blobs), str(part), str(parts)],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL) for part in range(parts)]
        self.taken: Taken | None = None  # once read

    def states(self, keys: pa.Array) -> tuple[np.ndarray, np.ndarray] | None:
        """(the states of ``keys`` in their order, whether the snapshot has each one), waiting for
        the children; None when one failed."""
        taken = self.read()
        if taken is None:
            return None
        where = positions(keys, taken.keys)  # both in key order: a binary search (none for the very same keys)
        found = where >= 0
        return taken.states[np.where(found, where, 0)], found

    def read(self) -> Taken | None:
        """What the children found, waiting for them; None when one failed or hung."""
        processes, self.processes = self.processes, []
        if not processes:
            return self.taken
        deadline = time.monotonic() + WAIT
        outputs: list[bytes] = []
        for process in processes:
            try:
                outputs.append(process.communicate(timeout=max(0.0, deadline - time.monotonic()))[0])
            except subprocess.TimeoutExpired:
                _stop(processes)
                return None
        if any(p.returncode != 0 for p in processes):
            return None
        parts = [_part(data) for data in outputs]
        if None in parts:
            return None
        self.taken = _joined(parts)  # type: ignore[arg-type]
        return self.taken

    def close(self) -> None:
        """Stop the children if they still run (their answer is not needed)."""
        processes, self.processes = self.processes, []
        _stop(processes)


def _stop(processes: list[subprocess.Popen]) -> None:
    """Kill the children still running and reap each one."""
    for process in processes:
        if process.poll() is None:
            process.kill()
        try:
            process.communicate()
        except ValueError:  # its output was read already
            pass


def _part(data: bytes) -> Taken | None:
    """What one child wrote, as a :class:`Taken`; None when it is not whole."""
    if len(data) < 16:
        return None
    n, length = int.from_bytes(data[:8], "little"), int.from_bytes(data[8:16], "little")
    end = 16 + 32 * n
    if len(data) < end + length:
        return None
    states = np.frombuffer(data, dtype=np.int64, count=4 * n, offset=16).reshape(n, 4)
    try:
        text = data[end:end + length].decode()
    except UnicodeDecodeError:  # a blob's name that is not UTF-8: the parent looks for itself
        return None
    sep = stat_blobs.SEPARATOR
    if (text.count(sep) + 1 if n else 0) != n or (n and not text) or (not n and text):
        return None
    others: dict[str, list[str]] = {}
    rest = data[end + length:].decode("utf-8", "surrogateescape")  # as os.listdir would name them
    for entry in rest.split(sep) if rest else ():
        folder, _, name = entry.partition("/")
        others.setdefault(folder, []).append(name)
    digest = hashlib.sha256(memoryview(data)[:end + length]).hexdigest()  # ~0.05 s per 100 MB
    return Taken((text,), states, others, digest)


def _joined(parts: list[Taken]) -> Taken:
    """The children's parts as one (they hold runs of folders in name order: keys stay in order)."""
    if len(parts) == 1:
        return parts[0]
    others = {folder: names for p in parts for folder, names in p.others.items()}
    digest = hashlib.sha256("".join(p.digest for p in parts).encode()).hexdigest()
    return Taken(tuple(t for p in parts for t in p.texts), np.concatenate([p.states for p in parts]), others, digest)
