"""What a render worker keeps loaded between scenes, least recently used first out.

A worker keeps every object and world it has loaded, so going back to one is a switch instead
of a re-import, but a spec with many large meshes or HDRIs must not grow a worker without bound:
:class:`Kept` gives up the least recently used entries beyond a count and a total cost (faces,
pixels). Plain Python, so the policy is testable without Blender.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator
from typing import Generic, TypeVar

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")


class Kept(Generic[K, V]):
    """An LRU map of loaded things bounded by ``max_count`` and the sum of ``cost(value)``
    (asked at each :meth:`evict`: a world's cost is known only once its HDRI is loaded)."""

    def __init__(self, max_count: int, max_cost: float, cost: Callable[[V], float]) -> None:
        self.max_count, self.max_cost, self.cost = max_count, max_cost, cost
        self.entries: OrderedDict[K, V] = OrderedDict()

    def __len__(self) -> int:
        return len(self.entries)

    def __contains__(self, key: K) -> bool:
        return key in self.entries

    def get(self, key: K) -> V | None:
        """The value kept under ``key`` (now the most recently used), or None."""
        if key not in self.entries:
            return None
        self.entries.move_to_end(key)
        return self.entries[key]

    def add(self, key: K, value: V) -> None:
        """Keep ``value`` as the most recently used; call :meth:`evict` to enforce the bounds."""
        self.entries[key] = value
        self.entries.move_to_end(key)

    def values(self) -> Iterator[V]:
        return iter(list(self.entries.values()))

    def evict(self) -> list[V]:
        """Remove and return the least recently used values beyond the bounds (the most recent
        one always stays, however costly, because the current job needs it)."""
        out = []
        while len(self.entries) > 1 and (len(self.entries) > self.max_count or self._cost() > self.max_cost):
            out.append(self.entries.popitem(last=False)[1])
        return out

    def _cost(self) -> float:
        return sum(self.cost(value) for value in self.entries.values())
