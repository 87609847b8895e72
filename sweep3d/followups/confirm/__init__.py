"""``sweep3d confirm``: a run's findings tested again on fresh renders.

:mod:`.claims` turns the findings ``run`` prints into regions of the parameters, :mod:`.draw`
draws fresh twin configurations inside and outside each, :mod:`.confirm` renders them through
the normal cached stages and judges them (statistics in
:mod:`sweep3d.results.confirmation`), and :mod:`.record` keeps the verdicts in the store's
``confirmations`` table (declared in :mod:`.stored`) for ``run``'s findings and the report.
"""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used. From outside, import through here.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.followups.confirm.claims import Claim, boundary_key, region_key, rule_key
    from sweep3d.followups.confirm.draw import Space, space_of
    from sweep3d.followups.confirm.record import mark, read_verdicts, status, write_verdicts
    from sweep3d.followups.confirm.run import (
        ConfirmResult,
        Twin,
        allotted,
        claims_of,
        confirm,
        distinct_renders,
        evidence_rate,
        render_rows,
        render_twins,
    )
    from sweep3d.followups.confirm.stored import CONFIRMATIONS, confirmation_key

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
