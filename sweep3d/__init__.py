"""sweep3d: find where vision models fail by rendering 3D scenes under systematic variation.

The package root imports neither bpy nor torch, so the CLI, the planner and the
store start fast; the render stage imports bpy only inside its worker processes.
``sweep3d.load`` and ``sweep3d.Experiment`` (the Python API, :mod:`sweep3d.api`) and
``sweep3d.plugins`` (the classes plug-ins subclass) are imported when first used; the errors a
user can fix (``SpecError``, ``PluginError`` and their base ``UserError``) are here, to catch.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from sweep3d.cache import declare_table_modules
from sweep3d.core import PluginError, SpecError, UserError

__version__ = "0.1.0"
__all__ = ["Experiment", "PluginError", "SpecError", "UserError", "load", "plugins"]

if TYPE_CHECKING:
    from sweep3d import plugins
    from sweep3d.api import Experiment, load

_LAZY = {"Experiment": "sweep3d.api", "load": "sweep3d.api"}

#: The modules declaring what the follow-ups keep in the store (their tables' contracts, their
#: folders). Named here, at the top, because the store must know every table whichever packages a
#: command imported (``cache verify`` or ``gc`` that did not know a table would skip its files);
#: the store imports them the first time it needs every table or meets one it does not know.
declare_table_modules("sweep3d.followups.stability.stored", "sweep3d.followups.realism.stored",
                      "sweep3d.followups.explain.stored", "sweep3d.followups.confirm.stored",
                      "sweep3d.results.findings")


def __getattr__(name: str) -> Any:
    """``sweep3d.Experiment``, ``sweep3d.load`` and ``sweep3d.plugins``, imported on first use."""
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    if name == "plugins":
        return importlib.import_module("sweep3d.plugins")
    raise AttributeError(f"module 'sweep3d' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The public names, those imported on first use included (``dir(sweep3d)`` lists ``load``;
    a notebook completes from it)."""
    return sorted({*__all__, "__version__", *(name for name in globals() if name.startswith("__"))})
