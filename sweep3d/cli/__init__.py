"""The ``sweep3d`` command line: plan, run, report, query."""

from __future__ import annotations

from sweep3d.cli.app import app, main

__all__ = ["app", "main"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles; from outside the package, import through here.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.cli.app import main

__getattr__, __dir__ = _exports(__name__, {
    "main": ("sweep3d.cli.app", "main"),
})
