"""The pipeline stages: plan → render → postprocess → infer → aggregate (→ report).

Each stage owns its plug-ins, its key recipe and its table; :mod:`.driver` runs render,
postprocess and infer the same way for every caller. ``builtin_catalogue()`` bundles every stage's
plug-ins for the spec loader (``sweep3d.load`` is the one way to load a spec).
"""

from __future__ import annotations

__all__ = ["builtin_catalogue"]

from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.lazy import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.stages.catalogue import builtin_catalogue

__getattr__, __dir__ = _exports(__name__, {
    'builtin_catalogue': ('sweep3d.stages.catalogue', 'builtin_catalogue'),
})
