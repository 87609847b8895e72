"""`sweep3d bench`: render time against image error and prediction agreement, per setting."""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.bench.apply import apply_setting
    from sweep3d.bench.budget import budget_chooser, check_budget
    from sweep3d.bench.measurement import (
        BenchRow,
        Setting,
        default_settings,
        measure,
        pareto,
        recommend,
        reference_settings,
        required_agreement,
    )
    from sweep3d.bench.plot import write_pareto_plot

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
