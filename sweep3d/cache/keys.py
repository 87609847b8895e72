"""Canonical serialisation and content hashes: the cache keys of every stage.

Equal configurations must hash equal and different ones differ, so the canonical form sorts
mapping keys, writes floats in their shortest round-trip form, folds -0.0 into 0.0, writes
integral floats as floats (1 and 1.0 are different types, and pydantic has already coerced a
float parameter to float), and refuses NaN and infinity outright.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from functools import lru_cache
from pathlib import Path
from typing import Any

KEY_LENGTH = 40  # hex characters of SHA-256 kept: 160 bits
FLOAT_TAG = "$f"  # floats are written as {"$f": repr}; mapping keys starting with "$" are escaped


def canonical(value: Any) -> str:
    """The canonical JSON text of ``value`` (dicts, lists, tuples, str, int, float, bool, None)."""
    return json.dumps(_normalise(value), sort_keys=True, separators=(",", ":"), ensure_ascii=False)


def _normalise(value: Any) -> Any:
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"cannot hash a non-finite number: {value!r}")
        return {FLOAT_TAG: repr(value + 0.0)}  # tagged so 1.0 and 1 differ; +0.0 folds -0.0
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise TypeError(f"mapping keys must be strings, got {k!r}")
            # Escape keys that start with "$" so no mapping can look like a tagged float.
            out["$" + k if k.startswith("$") else k] = _normalise(v)
        return out
    if isinstance(value, (list, tuple)):
        return [_normalise(v) for v in value]
    if hasattr(value, "item"):  # numpy scalar
        return _normalise(value.item())
    raise TypeError(f"cannot hash a {type(value).__name__}")


def digest(value: Any) -> str:
    """The cache key of ``value``: a hex SHA-256 prefix of its canonical form."""
    return hashlib.sha256(canonical(value).encode("utf-8")).hexdigest()[:KEY_LENGTH]


def file_digest(path: str | Path) -> str:
    """SHA-256 of a file's bytes, memoised on (path, size, mtime) so reruns do not re-read it."""
    stat = os.stat(path)
    return _file_digest(str(Path(path).resolve()), stat.st_size, stat.st_mtime_ns)


@lru_cache(maxsize=4096)
def _file_digest(path: str, size: int, mtime_ns: int) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:KEY_LENGTH]


def files_digest(paths: list[str | Path]) -> str:
    """One digest over several files (a mesh with its materials and textures), order-independent."""
    parts = sorted((Path(p).name, file_digest(p)) for p in paths)
    return digest(parts)
