"""Files that carry their own digest: a model's kept outputs (``store/outputs/``).

A kept output is a cache outside the tables, with no row to record its digest in, so its file
does: the array's ``.npy`` bytes, then :data:`DIGEST_TAG` and their hex SHA-256 (``np.load``
reads the array and ignores what follows). A file whose bytes no longer match, or that ends with
no digest (written before digests were kept, or rewritten since), is never used.
"""

from __future__ import annotations

import hashlib
import io
from pathlib import Path

import numpy as np

OUTPUTS_FOLDER = "outputs"  # under the store's root
SUFFIX = ".npy"
#: What follows the array's bytes in a kept file: this tag, then the hex SHA-256 of those bytes.
DIGEST_TAG = b"\nsweep3d.sha256:"
TRAILER = len(DIGEST_TAG) + 64


def pack(array: np.ndarray) -> bytes:
    """``array`` as ``.npy`` bytes followed by their digest (what :func:`unpack` checks)."""
    buffer = io.BytesIO()
    np.save(buffer, np.ascontiguousarray(array), allow_pickle=False)
    data = buffer.getvalue()
    return data + DIGEST_TAG + hashlib.sha256(data).hexdigest().encode()


def unpack(data: bytes) -> bytes | None:
    """The ``.npy`` bytes of a kept file when they match the digest it ends with; None when they
    do not, or it ends with none."""
    if len(data) <= TRAILER or data[-TRAILER:-64] != DIGEST_TAG:
        return None
    body = data[:-TRAILER]
    return body if hashlib.sha256(body).hexdigest().encode() == data[-64:] else None


def check_file(path: Path) -> str:
    """Why the kept file at ``path`` may not be used ("" when it may): for ``cache verify``."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        return exc.strerror or str(exc)
    if len(data) <= TRAILER or data[-TRAILER:-64] != DIGEST_TAG:
        return "no digest recorded: written before digests were kept, or rewritten since"
    return "" if unpack(data) is not None else "content does not match the SHA-256 recorded when it was written"
