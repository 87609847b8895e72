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
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from sweep3d.cache.keys import digest
from sweep3d.cache.store import Store, atomic_write

#: The tasks whose outputs are one array per image, kept when small.
KEPT_TASKS = ("classification", "raw")
MAX_BYTES = 64 * 1024  # per image: 1 000 float32 logits are 4 kB; a depth map is not kept
FOLDER = "outputs"


def outputs_key(model_digest: str, answers: str, task: str, image_key: str) -> str:
    """The key of one image's outputs. ``answers`` says whose they are (the backend; for ONNX Runtime
    standing in for torch, also how many ranks were checked against torch's)."""
    return digest({"stage": "outputs", "v": 1, "model": model_digest, "answers": answers, "task": task,
                   "image": image_key})


class KeptOutputs:
    """The kept outputs of one model, backend and task in one store."""

    def __init__(self, store: Store, model_digest: str, answers: str, task: str) -> None:
        self.root = store.root / FOLDER
        self.model_digest, self.answers, self.task = model_digest, answers, task

    def _path(self, image_key: str) -> Path:
        key = outputs_key(self.model_digest, self.answers, self.task, image_key)
        return self.root / key[:2] / f"{key}.npy"

    def load(self, image_keys: Sequence[str]) -> np.ndarray | None:
        """The batch's outputs stacked (N, ...) when every image's is kept and readable, else None."""
        if self.task not in KEPT_TASKS or not image_keys:
            return None
        arrays = []
        for key in image_keys:
            try:
                arrays.append(np.load(self._path(key), allow_pickle=False))
            except (OSError, ValueError):
                return None
        if len({(a.shape, a.dtype) for a in arrays}) != 1:
            return None
        return np.stack(arrays)

    def save(self, image_keys: Sequence[str], outputs: Any) -> None:
        """Keep each image's outputs, where the task's are one small array per image."""
        if self.task not in KEPT_TASKS or not isinstance(outputs, np.ndarray) or len(outputs) != len(image_keys):
            return
        if outputs[0].nbytes > MAX_BYTES:
            return
        for key, array in zip(image_keys, outputs):
            buffer = io.BytesIO()
            np.save(buffer, np.ascontiguousarray(array), allow_pickle=False)
            atomic_write(self._path(key), buffer.getvalue(), durable=False)  # a torn file reads as a miss
