"""One small registry pattern shared by every plug-in kind (controls, policies, models, evaluators).

Plug-ins register under a short name. A spec names them either by that short name or
as ``"package.module:Name"``, which imports the user's own module; an unknown name fails at
spec load with the list of valid names.
"""

from __future__ import annotations

import difflib
import importlib
from typing import Callable, Generic, Iterator, TypeVar

from sweep3d.errors import UserError

T = TypeVar("T")


class Registry(Generic[T]):
    """Maps short names to plug-ins of one kind.

    Each stage owns the registries of its plug-ins (rendered controls, post controls, policies,
    models, evaluators); the spec loader is handed them through a catalogue, so the spec layer
    never imports a stage.

    Args:
        kind: what the plug-ins are, for error messages ("control", "policy", ...).
    """

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._items: dict[str, T] = {}

    @classmethod
    def union(cls, kind: str, *parts: "Registry[T]") -> "Registry[T]":
        """One registry holding the plug-ins of ``parts`` (e.g. rendered and post controls).

        Raises:
            ValueError: if two parts register the same name.
        """
        merged: Registry[T] = cls(kind)
        for part in parts:
            for name in part.names():
                merged.register(name)(part.get(name))
        return merged

    def register(self, name: str) -> Callable[[T], T]:
        """Class or function decorator that registers the plug-in under ``name``."""

        def decorator(item: T) -> T:
            existing = self._items.get(name)
            if existing is not None and existing is not item:
                raise ValueError(f"{self.kind} {name!r} is already registered")
            self._items[name] = item
            return item

        return decorator

    def names(self) -> list[str]:
        return sorted(self._items)

    def __contains__(self, name: str) -> bool:
        """True for registered short names (``module:Name`` references are checked by :meth:`get`)."""
        return name in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def get(self, name: str) -> T:
        """Return the plug-in called ``name``, importing ``module:attr`` names on demand.

        Raises:
            UserError: if the name is unknown or the user's module cannot be imported.
        """
        if name in self._items:
            return self._items[name]
        if ":" in name:
            return self._import(name)
        close = difflib.get_close_matches(name, self._items, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise UserError(
            f"unknown {self.kind} {name!r}{hint}; valid: {', '.join(self.names())}, "
            f"or 'package.module:Name' for your own"
        )

    def _import(self, dotted: str) -> T:
        module_name, _, attr = dotted.partition(":")
        try:
            module = importlib.import_module(module_name)
        except ImportError as exc:
            if exc.name and not module_name.startswith(exc.name):  # the module is there; an import of its failed
                raise UserError(f"importing {self.kind} module {module_name!r} failed: {exc}") from None
            raise UserError(
                f"cannot import {self.kind} module {module_name!r}: {exc}; "
                "make sure it is installed or on PYTHONPATH"
            ) from None
        except Exception as exc:  # noqa: BLE001  (a syntax error or a raise in the user's module)
            raise UserError(
                f"importing {self.kind} module {module_name!r} failed: {type(exc).__name__}: {exc}"
            ) from None
        try:
            return getattr(module, attr)
        except AttributeError:
            raise UserError(f"module {module_name!r} has no {self.kind} named {attr!r}") from None
