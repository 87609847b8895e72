"""Blob integrity: the digest recorded in a blob's row, and reading a blob back safely.

Blobs are named by cache key, not by content, so the row that describes a blob records the
SHA-256 of its bytes when it is written; a reader compares against it. A blob that is missing,
does not match, or does not decode is reported as None, and the stage that needed it treats
it as never computed.
"""

from __future__ import annotations

import hashlib
import io

import numpy as np

from sweep3d.cache.store import Store


def sha256_bytes(data: bytes) -> str:
    """Hex SHA-256 of ``data``: the digest recorded in a blob's row."""
    return hashlib.sha256(data).hexdigest()


def blob_is_intact(data: bytes, digests: set[str]) -> bool:
    """True when ``data`` matches one of its rows' digests, or (none recorded) decodes as an image."""
    if digests:
        return sha256_bytes(data) in digests
    return decode_image(data) is not None


def decode_image(data: bytes) -> np.ndarray | None:
    """PNG bytes as float32 (H, W, 3) in [0, 1], or None when they do not decode."""
    from sweep3d.pixels import decode_png

    try:
        return decode_png(io.BytesIO(data))  # type: ignore[arg-type]  (PIL opens file objects too)
    except Exception:  # noqa: BLE001  (any decoder failure means a damaged blob)
        return None


def load_image(store: Store, key: str, digests: set[str] | None) -> np.ndarray | None:
    """The blob ``key`` as float32 (H, W, 3) in [0, 1]; None if it is missing or damaged.

    Args:
        digests: the SHA-256 digests its rows recorded (empty or None: only check it decodes).
    """
    try:
        data = store.blob_path(key).read_bytes()
    except OSError:
        return None
    if digests and sha256_bytes(data) not in digests:
        return None
    return decode_image(data)
