"""`sweep3d bench`: render time against image error and prediction agreement, per setting."""

from sweep3d.bench.apply import apply_setting
from sweep3d.bench.measure import (
    BenchRow,
    Setting,
    default_settings,
    measure,
    recommend,
)

__all__ = ["BenchRow", "Setting", "apply_setting", "default_settings", "measure", "recommend"]
