"""``sweep3d explain``: the nearest change that fixes each failure (see :mod:`.search`, the pure
search, and :mod:`.driver`, which answers its probes through the stages)."""

from __future__ import annotations

__all__ = ["ExplainResult", "explain_spec", "print_explained"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles; from outside the package, import through here.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.explain.driver import ExplainResult, explain_spec, print_explained

__getattr__, __dir__ = _exports(__name__, {
    "ExplainResult": ("sweep3d.explain.driver", "ExplainResult"),
    "explain_spec": ("sweep3d.explain.driver", "explain_spec"),
    "print_explained": ("sweep3d.explain.driver", "print_explained"),
})
