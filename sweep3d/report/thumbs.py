"""Thumbnails embedded in the report: one per image key, downscaled, within a count and a size budget.

Panels ask for an image with :meth:`Thumbnails.want` and get its index in the page's single
list of data URIs (``<script id="thumbs">``), so an image shown by several panels travels once.
The page embeds a sample, never one image per result: the panels ask for the images they show
(the worst failures, failure-mode and confusion examples), then the explorer fills what is left
of :data:`MAX_IMAGES` (see :attr:`Thumbnails.remaining`). Images are encoded in the order first
asked for; beyond either budget, later ones are left out (``null`` in the list; the page shows a
placeholder), so a report stays small at any scale.
A blob is embedded only if it matches a SHA-256 its rows recorded: a damaged one is shown as a
placeholder saying so (:attr:`Thumbnails.problems`), never as the picture it no longer is.
Boxes and masks are drawn on a thumbnail when the report hands them over (see
:mod:`sweep3d.report.overlays`); such a thumbnail keeps full colour resolution, so thin coloured
outlines keep their colour through JPEG.
"""

from __future__ import annotations

import base64
import io
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Mapping

import pyarrow as pa
import pyarrow.compute as pc
from PIL import Image

from sweep3d.cache import BLOB_TABLES, DIGEST_COLUMN, KEY_COLUMN, Store, sha256_bytes
from sweep3d.report.overlays import Overlay, draw_overlay

#: Longest side of a thumbnail by the number of distinct images in the report: 96 px up to
#: 2500 images, else 64 px (a 64 px render is about 2 kB as JPEG).
SIZES = ((2500, 96), (None, 64))
BUDGET = 16_000_000  # characters of data URIs at most (plotly.js adds ~4.6 MB to the page)
MAX_IMAGES = 2000  # distinct images at most
JPEG_QUALITY = 80
MISSING = "not in the store"
DAMAGED = "damaged"  # fails its SHA-256 check


class Thumbnails:
    """The report's images, by image key.

    Args:
        store: the store holding the image blobs.
        expected: how many distinct images the report will show (chooses the thumbnail size).
        budget: the most characters of data URIs to embed.
        limit: the most images to embed.
    """

    def __init__(self, store: Store, expected: int, budget: int = BUDGET, limit: int = MAX_IMAGES) -> None:
        self.store = store
        self.size = thumbnail_size(min(expected, limit))
        self.budget = budget
        self.limit = limit
        self._index: dict[str, int] = {}
        self.missing = 0  # blobs not in the store
        self.damaged = 0  # blobs that fail their SHA-256 check
        self.left_out = 0  # images beyond the budget
        self.problems: dict[int, str] = {}  # index -> why it has no image (MISSING or DAMAGED)

    def want(self, key: str) -> int:
        """The index of ``key``'s thumbnail in :meth:`data_uris`, registering it if new."""
        return self._index.setdefault(key, len(self._index))

    def __len__(self) -> int:
        return len(self._index)

    @property
    def remaining(self) -> int:
        """How many more images fit in :attr:`limit`."""
        return max(0, self.limit - len(self._index))

    def keys(self) -> list[str]:
        """The image keys asked for, in the order first asked for."""
        return list(self._index)

    def data_uris(self, workers: int | None = None, overlays: Mapping[str, Overlay] | None = None
                  ) -> list[str | None]:
        """Encode every image asked for, in the order first asked for.

        Args:
            overlays: image key → what to draw on its thumbnail (boxes, masks).

        Returns:
            One data URI per index (None for a blob missing, damaged or beyond the budget; see
            :attr:`problems` for why).
        """
        keys = self.keys()[:self.limit]
        digests = recorded_digests(self.store, keys)
        overlays = overlays or {}
        jobs = [(self.store.blob_path(key), digests.get(key, set()), overlays.get(key)) for key in keys]
        workers = workers or min(8, os.cpu_count() or 1)
        with ThreadPoolExecutor(workers) as pool:  # PIL releases the GIL while decoding and encoding
            encoded = list(pool.map(lambda job: encode_thumbnail(job[0], job[1], self.size, job[2]), jobs))
        uris: list[str | None] = []
        spent = 0
        self.missing = self.damaged = self.left_out = 0
        self.problems = {}
        for index, (uri, problem) in enumerate(encoded):
            if problem is not None:
                self.problems[index] = problem
                self.missing += problem == MISSING
                self.damaged += problem == DAMAGED
            elif spent + len(uri or "") > self.budget:
                self.left_out += 1
                uri = None
            else:
                spent += len(uri or "")
            uris.append(uri)
        self.left_out += len(self._index) - len(keys)
        return uris + [None] * (len(self._index) - len(keys))


def recorded_digests(store: Store, keys: list[str]) -> dict[str, set[str]]:
    """Key → the SHA-256 digests its rows recorded, for ``keys``, over the tables whose rows own a
    blob (an image key is a render key when no post control changes the render). Filtered before
    it becomes Python objects: a store of 10^6 images is read as one column, not a dict."""
    digests: dict[str, set[str]] = {}
    wanted = pa.array(keys, pa.string())
    for table in BLOB_TABLES:
        key = KEY_COLUMN[table]
        data = store.table(table, [key, DIGEST_COLUMN])
        if data is None or DIGEST_COLUMN not in data.column_names:
            continue
        data = data.filter(pc.is_in(data.column(key), value_set=wanted))
        for k, d in zip(data.column(key).to_pylist(), data.column(DIGEST_COLUMN).to_pylist()):
            entry = digests.setdefault(k, set())
            if d:
                entry.add(d)
    return digests


def thumbnail_size(images: int) -> int:
    """The longest side of thumbnails for a report showing ``images`` distinct images."""
    return next(size for limit, size in SIZES if limit is None or images <= limit)


def encode_thumbnail(path: Path, digests: set[str], size: int,
                     overlay: Overlay | None = None) -> tuple[str | None, str | None]:
    """A JPEG data URI of the image at ``path`` downscaled to ``size`` (longest side), checked first.

    Args:
        digests: the SHA-256 digests its rows recorded (empty: it only has to decode).
        overlay: boxes and masks to draw on it, in the stored image's pixels.

    Returns:
        (the data URI, None), or (None, :data:`MISSING` or :data:`DAMAGED`) when the file is
        not there, does not match a recorded digest or is not an image.
    """
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return None, MISSING
    except OSError:
        return None, DAMAGED
    if digests and sha256_bytes(data) not in digests:
        return None, DAMAGED
    try:
        with Image.open(io.BytesIO(data)) as img:
            img = img.convert("RGB")
            full = img.size
            img.thumbnail((size, size), Image.Resampling.LANCZOS)
    except (OSError, ValueError):
        return None, DAMAGED
    drawn = overlay is not None and not overlay.empty
    if drawn:
        img = draw_overlay(img, overlay, (img.width / full[0], img.height / full[1]))
    buf = io.BytesIO()
    img.save(buf, format="JPEG", quality=JPEG_QUALITY, optimize=True, **({"subsampling": 0} if drawn else {}))
    return "data:image/jpeg;base64," + base64.b64encode(buf.getvalue()).decode("ascii"), None
