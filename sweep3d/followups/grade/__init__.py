"""``sweep3d grade``: one graded answer per finding (solid, renderer-sensitive, fragile, not
replicated, inconclusive or untested), from the follow-ups' checks run as plans under one budget.

:mod:`.decide` turns the checks' verdicts into a grade (pure); :mod:`.run` makes the checks and
records the grades as the ``findings`` view's rows (:mod:`sweep3d.results.findings`).
"""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used. From outside, import through here.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.followups.grade.decide import Evidence, evidence_of, grade, second_opinion, single, steady_pairs
    from sweep3d.followups.grade.run import Graded, grade_findings, other_engine

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
