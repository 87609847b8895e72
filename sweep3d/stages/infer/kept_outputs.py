"""A model's raw outputs per image, kept so that a changed evaluator re-evaluates without the model.

Prediction keys hold the evaluator (its kind, settings and, for a user's, its code), but what the
model returns for an image does not depend on it. Where that is one small array per image
(classification logits, a ``raw`` task's output up to :data:`MAX_BYTES`), the infer stage keeps
each image's array in ``store/outputs/ab/<key>.npy`` under :func:`outputs_key` (the model's
digest, whose answers they are, the task and the image) and reads a batch's back
instead of running the model when all of them are there. Boxes, detections and score maps are
not kept: their tasks run the model again. The files are a cache: a missing or unreadable one
means the model runs; ``sweep3d cache gc`` leaves them alone, and deleting the folder loses nothing
but time.

Each file ends with the SHA-256 of its array's ``.npy`` bytes, recorded when it was written
(:mod:`sweep3d.cache.digested`; ``np.load`` reads the array and ignores it). A file whose bytes no
longer match (edited in place, its mtime restored or not) is never used: the model runs for its
batch again, with a warning, and the file is written anew; ``sweep3d cache verify`` reports it.
"""

from __future__ import annotations

import io
import logging
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from sweep3d.cache import OUTPUTS_FOLDER, SUFFIX, Store, atomic_write, digest, pack, unpack

#: The tasks whose outputs are one array per image, kept when small.
KEPT_TASKS = ("classification", "raw")
MAX_BYTES = 64 * 1024  # per image: 1 000 float32 logits are 4 kB; a depth map is not kept
log = logging.getLogger("sweep3d.store")


def outputs_key(model_digest: str, answers: str, task: str, image_key: str) -> str:
    """The key of one image's outputs. ``answers`` says whose they are (the backend; for ONNX Runtime
    standing in for torch, also how many ranks were checked against torch's)."""
    return digest({"stage": "outputs", "v": 1, "model": model_digest, "answers": answers, "task": task,
                   "image": image_key})


class KeptOutputs:
    """The kept outputs of one model, backend and task in one store."""

    def __init__(self, store: Store, model_digest: str, answers: str, task: str) -> None:
        self.root = store.root / OUTPUTS_FOLDER
        self.model_digest, self.answers, self.task = model_digest, answers, task
        self._writer: ThreadPoolExecutor | None = None
        self._pending: list[Future] = []
        self._unwritten: dict[Path, bytes] = {}  # saved, not yet on disk: what load reads meanwhile

    def _path(self, image_key: str) -> Path:
        key = outputs_key(self.model_digest, self.answers, self.task, image_key)
        return self.root / key[:2] / f"{key}{SUFFIX}"

    def load(self, image_keys: Sequence[str]) -> np.ndarray | None:
        """The batch's outputs stacked (N, ...) when every image's is kept, readable and matches
        its digest, else None (the model runs; a file that does not match is said, once per batch)."""
        if self.task not in KEPT_TASKS or not image_keys:
            return None
        arrays: list[np.ndarray] = []
        mismatched: list[Path] = []
        for key in image_keys:
            path = self._path(key)
            waiting = self._unwritten.get(path)  # saved, its file not written yet
            array = _read(path) if waiting is None else _array(waiting)
            if isinstance(array, np.ndarray):
                arrays.append(array)
            elif array == "mismatch":
                mismatched.append(path)
        if mismatched:
            _warn(mismatched, self.root.parent)
        if len(arrays) != len(image_keys) or len({(a.shape, a.dtype) for a in arrays}) != 1:
            return None
        return np.stack(arrays)

    def save(self, image_keys: Sequence[str], outputs: Any) -> None:
        """Keep each image's outputs, where the task's are one small array per image. The files are
        written by one thread of their own (a file an image costs the disk more than the model
        costs the CPU on a slow disk: benchmarks/RESULTS.md, issue 37) until :meth:`close`; a
        write that failed (a full disk) is raised by the next call."""
        if self.task not in KEPT_TASKS or not isinstance(outputs, np.ndarray) or len(outputs) != len(image_keys):
            return
        if outputs[0].nbytes > MAX_BYTES:
            return
        files = [(self._path(key), pack(array)) for key, array in zip(image_keys, outputs)]
        if self._writer is None:
            self._writer = ThreadPoolExecutor(1, thread_name_prefix="sweep3d-kept-outputs")
        self._raise_failed()
        self._unwritten.update(files)
        self._pending.append(self._writer.submit(self._write, files))

    def _write(self, files: list[tuple[Path, bytes]]) -> None:
        for path, data in files:
            atomic_write(path, data, durable=False)  # a torn file reads as a mismatch
            self._unwritten.pop(path, None)

    def close(self) -> None:
        """Wait for the files being written; raise a write that failed."""
        if self._writer is not None:
            self._writer.shutdown(wait=True)
            self._writer = None
        self._raise_failed()

    def _raise_failed(self) -> None:
        done = [f for f in self._pending if f.done()]
        self._pending = [f for f in self._pending if not f.done()]
        for future in done:
            future.result()


def _read(path: Path) -> np.ndarray | str:
    """The array kept at ``path``; "missing" when there is none to read, "mismatch" when its bytes
    do not match the digest it was written with (or it has none)."""
    try:
        data = path.read_bytes()
    except OSError:
        return "missing"
    return _array(data)


def _array(data: bytes) -> np.ndarray | str:
    """The array a kept file's bytes hold, or "mismatch"."""
    body = unpack(data)
    if body is None:
        return "mismatch"
    try:
        return np.load(io.BytesIO(body), allow_pickle=False)
    except (OSError, ValueError):
        return "mismatch"


def _warn(paths: list[Path], root: Path) -> None:
    """One line for a batch's kept outputs that do not match their digests."""
    sample = ", ".join(str(p.relative_to(root)) if p.is_relative_to(root) else p.name for p in paths[:2])
    log.warning(f"warning: {len(paths)} kept model output{'s' * (len(paths) > 1)} ({sample}"
                f"{', …' if len(paths) > 2 else ''}) {'do' if len(paths) > 1 else 'does'} not match the digest "
                "recorded when written (changed since, or kept before digests were); running the model again for "
                "their batch, and keeping its outputs anew")
