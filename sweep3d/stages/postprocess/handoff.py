"""Post-processed images handed from the postprocess stage to inference in memory.

With ``[postprocess] store = "none"`` an image is not written to the store: the stage puts its
8-bit pixels here and the infer stage takes them. Encoding a PNG, writing it and decoding it
again cost more per image than the model on two cores (benchmarks/RESULTS.md, the image path).
The stage also hands over the render of a job whose image is its render (no post control
changes it), which it has decoded anyway. The handoff is bounded: past :data:`LIMIT` images the
oldest is forgotten (inference far behind, or a render whose prediction is cached), and inference
reads or makes it again, as it does for an image of an earlier run. The stage, on every core,
could make images faster than inference takes them: it waits for room while inference is taking
images (:meth:`ImageHandoff.wait_for_room`), rather than make images only to have them forgotten.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict

import numpy as np

#: Images held at most (224² RGB: about 150 kB each, so about 300 MB).
LIMIT = 2048
#: Seconds without a take after which a full handoff no longer holds the stage back (nothing takes
#: the images: a pass without inference, or one whose predictions are cached).
STALL = 5.0


class ImageHandoff:
    """Image key → uint8 (H, W, 3) pixels, each taken once; safe between the stages' threads."""

    def __init__(self, limit: int = LIMIT) -> None:
        self._images: OrderedDict[str, np.ndarray] = OrderedDict()
        self._lock = threading.Lock()
        self._taken = threading.Condition(self._lock)
        self._last_take: float | None = None  # time.monotonic() of the last take; None: none yet
        self.limit = limit

    def put(self, key: str, pixels: np.ndarray) -> None:
        """Keep ``pixels`` for ``key``, forgetting the oldest image when the handoff is full."""
        with self._lock:
            self._images[key] = pixels
            if len(self._images) > self.limit:
                self._images.popitem(last=False)

    def take(self, key: str) -> np.ndarray | None:
        """The pixels kept for ``key``, forgotten here; None when none are kept."""
        with self._lock:
            self._last_take = time.monotonic()
            self._taken.notify_all()
            return self._images.pop(key, None)

    def wait_for_room(self) -> None:
        """Wait while the handoff is full and something takes images (a take in the last
        :data:`STALL` seconds); at once when nothing has taken one yet."""
        with self._taken:
            while len(self._images) >= self.limit and self._last_take is not None:
                left = STALL - (time.monotonic() - self._last_take)
                if left <= 0:
                    return
                self._taken.wait(left)

    def __len__(self) -> int:
        return len(self._images)
