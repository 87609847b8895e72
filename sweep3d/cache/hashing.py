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
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

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
    if isinstance(value, Hole):
        return _HOLE_MARK.format(value.name)
    raise TypeError(f"cannot hash a {type(value).__name__}")


def digest(value: Any) -> str:
    """The cache key of ``value``: a hex SHA-256 prefix of its canonical form."""
    return hashlib.sha256(canonical(value).encode("utf-8")).hexdigest()[:KEY_LENGTH]


def digests(texts: Iterable[str]) -> list[str]:
    """The cache key of each canonical text: :func:`digest` for values already written out."""
    sha = hashlib.sha256
    return [sha(text.encode("utf-8")).hexdigest()[:KEY_LENGTH] for text in texts]


@dataclass(frozen=True)
class Hole:
    """A place in a value left open by :func:`canonical_pieces`, to be filled with canonical text."""

    name: str


_HOLE_MARK = "\ue000sweep3d-hole:{}\ue000"  # a private-use character no key part contains
_HOLE_TEXT = re.compile('"\ue000sweep3d-hole:(.*?)\ue000"')


def canonical_pieces(value: Any) -> tuple[list[str], list[str]]:
    """The canonical text of ``value`` split at its :class:`Hole` s: (pieces, hole names in text order).

    Filling hole *i* with the canonical text of a value *v_i*, ``pieces[0] + t_0 + pieces[1] + ...``
    is ``canonical`` of ``value`` with the holes replaced by the *v_i*, so a batch of keys that
    differ in a few values is written without walking the whole value per key.

    Raises:
        ValueError: when the text cannot be split unambiguously (a string in ``value`` that
            imitates a hole): callers then write each key in full.
    """
    holes = _holes(value)
    parts = _HOLE_TEXT.split(canonical(value))
    names = parts[1::2]
    if sorted(names) != sorted(holes) or len(set(names)) != len(names):
        raise ValueError("ambiguous holes in a canonical value")
    return parts[0::2], names


class Template:
    """The canonical text of a value with :class:`Hole` s, filled per key from columns of texts."""

    def __init__(self, value: Any) -> None:
        self.pieces, self.names = canonical_pieces(value)

    @classmethod
    def of(cls, pieces: Sequence[str], names: Sequence[str]) -> Template:
        """A template from pieces and hole names already split by :func:`canonical_pieces`."""
        template = cls.__new__(cls)
        template.pieces, template.names = list(pieces), list(names)
        return template

    def fill(self, strings: Sequence[str] = (), **texts: Sequence[str]) -> list[str]:
        """One canonical text per row: hole ``name`` filled with ``texts[name][row]`` (already
        canonical), or for the names in ``strings``, with that plain string (a key) as JSON writes it."""
        p = list(self.pieces)
        for i, name in enumerate(self.names):
            if name in strings:  # a key's JSON text is the key in quotes: move them into the pieces
                p[i], p[i + 1] = p[i] + '"', '"' + p[i + 1]
        columns = [texts[name] for name in self.names]
        if len(columns) == 1:
            a, b = p
            return [a + x + b for x in columns[0]]
        form = "%s".join(piece.replace("%", "%%") for piece in p)
        return [form % row for row in zip(*columns)]


def _holes(value: Any) -> list[str]:
    if isinstance(value, Hole):
        return [value.name]
    if isinstance(value, dict):
        return [name for v in value.values() for name in _holes(v)]
    if isinstance(value, (list, tuple)):
        return [name for v in value for name in _holes(v)]
    return []


def float_texts(values: np.ndarray) -> np.ndarray:
    """The canonical text of each float in ``values`` (what :func:`canonical` writes for it), as
    an object array.

    Each distinct value is written once (a grid repeats a few values many times).

    Raises:
        ValueError: for NaN or infinity, as :func:`canonical` does.
    """
    values = np.asarray(values, dtype=np.float64)
    if not np.isfinite(values).all():
        raise ValueError(f"cannot hash a non-finite number: {values[~np.isfinite(values)][0]!r}")
    distinct, inverse = np.unique(values + 0.0, return_inverse=True)  # + 0.0 folds -0.0
    texts = np.array([f'{{"{FLOAT_TAG}":"{v!r}"}}' for v in distinct.tolist()], dtype=object)
    return texts[inverse.reshape(-1)]


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
