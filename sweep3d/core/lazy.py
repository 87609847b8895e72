"""PEP 562 lazy exports for a package ``__init__``: the package names what it offers, and a name's
module is imported on first use, so importing a package (``import sweep3d.plugins`` in every render
worker) loads only the modules whose names are used, and no import cycle runs through an ``__init__``."""

from __future__ import annotations

import importlib
from typing import Any, Callable


def exports(package: str, names: dict[str, tuple[str, str]]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package``: ``names`` maps an exported name to (module, name there)."""
    module = importlib.import_module(package)

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
