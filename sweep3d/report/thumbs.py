"""Thumbnails embedded in the report: one per image key, downscaled, within a size budget.

Panels ask for an image with :meth:`Thumbnails.want` and get its index in the page's single
list of data URIs (``<script id="thumbs">``), so an image shown by several panels travels once.
Images are encoded in the order first asked for; once the budget is spent, later ones are left
out (``null`` in the list; the page shows a placeholder), so a report stays small at any scale.
"""

from __future__ import annotations

import base64
import io
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from PIL import Image

from sweep3d.cache.store import Store

#: Longest side of a thumbnail by the number of distinct images in the report: 96 px up to
#: 2500 images, else 64 px (a 64 px render is about 2 kB as JPEG).
SIZES = ((2500, 96), (None, 64))
BUDGET = 16_000_000  # characters of data URIs at most (plotly.js adds ~4.6 MB to the page)
JPEG_QUALITY = 80


class Thumbnails:
    """The report's images, by image key.

    Args:
        store: the store holding the image blobs.
        expected: how many distinct images the report will show (chooses the thumbnail size).
        budget: the most characters of data URIs to embed.
    """

    def __init__(self, store: Store, expected: int, budget: int = BUDGET) -> None:
        self.store = store
        self.size = thumbnail_size(expected)
        self.budget = budget
        self._index: dict[str, int] = {}
        self.missing = 0  # blobs not in the store
        self.left_out = 0  # images beyond the budget

    def want(self, key: str) -> int:
        """The index of ``key``'s thumbnail in :meth:`data_uris`, registering it if new."""
        return self._index.setdefault(key, len(self._index))

    def __len__(self) -> int:
        return len(self._index)

    def data_uris(self, workers: int | None = None) -> list[str | None]:
        """Encode every image asked for, in the order first asked for.

        Returns:
            One data URI per index (None for a blob missing from the store or beyond the budget).
        """
        paths = [self.store.blob_path(key) for key in self._index]
        workers = workers or min(8, os.cpu_count() or 1)
        with ThreadPoolExecutor(workers) as pool:  # PIL releases the GIL while decoding and encoding
            encoded = list(pool.map(lambda p: encode_thumbnail(p, self.size), paths))
        uris: list[str | None] = []
        spent = 0
        self.missing = self.left_out = 0
        for uri in encoded:
            if uri is None:
                self.missing += 1
            elif spent + len(uri) > self.budget:
                self.left_out += 1
                uri = None
            else:
                spent += len(uri)
            uris.append(uri)
        return uris


def thumbnail_size(images: int) -> int:
    """The longest side of thumbnails for a report showing ``images`` distinct images."""
    return next(size for limit, size in SIZES if limit is None or images <= limit)


def encode_thumbnail(path: Path, size: int) -> str | None:
    """A JPEG data URI of the image at ``path`` downscaled to ``size`` (longest side).

    Returns:
        None if the file is missing or not an image (the page shows a placeholder instead).
    """
    try:
        with Image.open(path) as img:
            img = img.convert("RGB")
            img.thumbnail((size, size), Image.Resampling.LANCZOS)
    except (OSError, ValueError):
        return None
    buf = io.BytesIO()
    img.save(buf, format="JPEG", quality=JPEG_QUALITY, optimize=True)
    return "data:image/jpeg;base64," + base64.b64encode(buf.getvalue()).decode("ascii")
