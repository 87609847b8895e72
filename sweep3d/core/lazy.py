"""PEP 562 lazy exports for a package ``__init__``: the package names what it offers, and a name's
module is imported on first use, so importing a package (``import sweep3d.plugins`` in every render
worker) loads only the modules whose names are used, and no import cycle runs through an ``__init__``."""

from __future__ import annotations

import ast
import importlib
from typing import Any, Callable


def exports(package: str,
            names: dict[str, tuple[str, str]] | None = None) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package``: ``names`` maps an exported name to (module, name there).

    Without ``names`` the package's one listing is its ``if TYPE_CHECKING:`` block of imports
    (what a type checker and an editor read too): the names and their modules are read from it
    (:func:`listed`), and ``__all__`` is set from it."""
    module = importlib.import_module(package)
    if names is None:
        names = listed(module.__file__)
        module.__all__ = list(names)

    def __getattr__(name: str) -> Any:
        if name not in names:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        source, attr = names[name]
        value = getattr(importlib.import_module(source), attr)
        setattr(module, name, value)  # cached: the next look-up is a plain attribute
        return value

    def __dir__() -> list[str]:
        return sorted({*names, *vars(module)})

    return __getattr__, __dir__


def listed(path: str) -> dict[str, tuple[str, str]]:
    """The names a package ``__init__`` at ``path`` imports under ``if TYPE_CHECKING:`` (or
    ``_TYPE_CHECKING``), each → (its module, its name there), in the order written."""
    with open(path, encoding="utf-8") as file:
        tree = ast.parse(file.read(), path)
    names: dict[str, tuple[str, str]] = {}
    for node in tree.body:
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id.endswith("TYPE_CHECKING"):
            for statement in node.body:
                if isinstance(statement, ast.ImportFrom) and statement.module and not statement.level:
                    for alias in statement.names:
                        names[alias.asname or alias.name] = (statement.module, alias.name)
    return names
