"""`sweep3d bench`: render time against image error and prediction agreement, per setting."""

from __future__ import annotations

from sweep3d.bench.measure import (
    BenchRow,
    Setting,
    default_settings,
    measure,
    recommend,
)

__all__ = ["BenchRow", "Setting", "apply_setting", "default_settings", "measure", "recommend"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.lazy import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.bench.apply import apply_setting

__getattr__, __dir__ = _exports(__name__, {
    'apply_setting': ('sweep3d.bench.apply', 'apply_setting'),
})
