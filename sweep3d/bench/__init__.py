"""`sweep3d bench`: render time against image error and prediction agreement, per setting."""

from __future__ import annotations

from sweep3d.bench.measurement import BenchRow, Setting, default_settings, measure, recommend

__all__ = [
    "BenchRow", "Setting", "apply_setting", "budget_chooser", "check_budget", "default_settings",
    "measure", "pareto", "recommend", "reference_settings", "required_agreement", "write_pareto_plot"
]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.bench.apply import apply_setting
    from sweep3d.bench.budget import budget_chooser, check_budget
    from sweep3d.bench.measurement import (
        Setting,
        default_settings,
        measure,
        pareto,
        recommend,
        reference_settings,
        required_agreement,
    )
    from sweep3d.bench.plot import write_pareto_plot

__getattr__, __dir__ = _exports(__name__, {
    "Setting": ("sweep3d.bench.measurement", "Setting"),
    "apply_setting": ("sweep3d.bench.apply", "apply_setting"),
    "budget_chooser": ("sweep3d.bench.budget", "budget_chooser"),
    "check_budget": ("sweep3d.bench.budget", "check_budget"),
    "default_settings": ("sweep3d.bench.measurement", "default_settings"),
    "measure": ("sweep3d.bench.measurement", "measure"),
    "pareto": ("sweep3d.bench.measurement", "pareto"),
    "recommend": ("sweep3d.bench.measurement", "recommend"),
    "reference_settings": ("sweep3d.bench.measurement", "reference_settings"),
    "required_agreement": ("sweep3d.bench.measurement", "required_agreement"),
    "write_pareto_plot": ("sweep3d.bench.plot", "write_pareto_plot"),
})
