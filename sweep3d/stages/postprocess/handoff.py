"""Post-processed images handed from the postprocess stage to inference in memory.

With ``[postprocess] store = "none"`` an image is not written to the store: the stage puts its
8-bit pixels here and the infer stage takes them. Encoding a PNG, writing it and decoding it
again cost more per image than the model on two cores (benchmarks/RESULTS.md, the image path).
The handoff is bounded: past :data:`LIMIT` images (inference far behind) an image is not kept,
and inference makes it again from its render, as it does for an image of an earlier run.
"""

from __future__ import annotations

import threading

import numpy as np

#: Images held at most (224² RGB: about 150 kB each, so about 300 MB).
LIMIT = 2048


class ImageHandoff:
    """Image key → uint8 (H, W, 3) pixels, each taken once; safe between the stages' threads."""

    def __init__(self, limit: int = LIMIT) -> None:
        self._images: dict[str, np.ndarray] = {}
        self._lock = threading.Lock()
        self.limit = limit

    def put(self, key: str, pixels: np.ndarray) -> None:
        """Keep ``pixels`` for ``key`` unless the handoff is full."""
        with self._lock:
            if len(self._images) < self.limit:
                self._images[key] = pixels

    def take(self, key: str) -> np.ndarray | None:
        """The pixels kept for ``key``, forgotten here; None when none are kept."""
        with self._lock:
            return self._images.pop(key, None)

    def __len__(self) -> int:
        return len(self._images)
