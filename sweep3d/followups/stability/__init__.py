"""The stability check (``sweep3d stability``): which verdicts changes no eye sees can flip.

:mod:`~sweep3d.followups.stability.changes` makes the changes and computes margins from logits;
:mod:`~sweep3d.followups.stability.check` samples a run's results, re-infers and stores the rows;
:mod:`~sweep3d.followups.stability.scene` re-renders the sampled jobs' scene neighbours
(:mod:`~sweep3d.followups.stability.neighbours`) and compares their verdicts. The views that
turn the rows into flip rates and the ``fragile`` column are :mod:`sweep3d.results.fragile`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.followups.stability.check import DEFAULT_SAMPLE, check_stability
    from sweep3d.followups.stability.scene import neighbours_per_image
    from sweep3d.followups.stability.sequential import ALPHA, UNDECIDED, look_z, needed

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
