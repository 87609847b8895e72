"""The spec: pydantic models of the TOML file, its loader, and the search space it defines.

This layer imports no stage: the plug-ins a spec names come in through a :class:`Catalogue`.
"""

from __future__ import annotations

__all__ = ["Catalogue", "Choice", "ControlInstance", "Fixed", "Framing", "LoadedSpec", "Range", "Space", "Spec",
           "read_spec"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.lazy import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.spec.catalogue import Catalogue
    from sweep3d.spec.framing import Framing
    from sweep3d.spec.loader import ControlInstance, LoadedSpec
    from sweep3d.spec.models import Spec
    from sweep3d.spec.params import Choice, Fixed, Range, Space
    from sweep3d.spec.sources import read_spec

__getattr__, __dir__ = _exports(__name__, {
    'Catalogue': ('sweep3d.spec.catalogue', 'Catalogue'),
    'Choice': ('sweep3d.spec.params', 'Choice'),
    'ControlInstance': ('sweep3d.spec.loader', 'ControlInstance'),
    'Fixed': ('sweep3d.spec.params', 'Fixed'),
    'Framing': ('sweep3d.spec.framing', 'Framing'),
    'LoadedSpec': ('sweep3d.spec.loader', 'LoadedSpec'),
    'Range': ('sweep3d.spec.params', 'Range'),
    'Space': ('sweep3d.spec.params', 'Space'),
    'Spec': ('sweep3d.spec.models', 'Spec'),
    'read_spec': ('sweep3d.spec.sources', 'read_spec'),
})
