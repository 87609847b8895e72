"""``sweep3d confirm``: a run's findings tested again on fresh renders.

:mod:`.claims` turns the findings ``run`` prints into regions of the parameters, :mod:`.draw`
draws fresh twin configurations inside and outside each, :mod:`.confirm` renders them through
the normal cached stages and judges them (statistics in
:mod:`sweep3d.results.confirmation`), and :mod:`.record` keeps the verdicts in the store
for ``run``'s findings and the report.
"""

from __future__ import annotations

__all__ = ["ConfirmResult", "boundary_key", "confirm", "mark", "read_verdicts", "region_key", "rule_key"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles; from outside the package, import through here.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.followups.confirm.claims import boundary_key, region_key, rule_key
    from sweep3d.followups.confirm.record import mark, read_verdicts
    from sweep3d.followups.confirm.run import ConfirmResult, confirm

__getattr__, __dir__ = _exports(__name__, {
    "ConfirmResult": ("sweep3d.followups.confirm.run", "ConfirmResult"),
    "boundary_key": ("sweep3d.followups.confirm.claims", "boundary_key"),
    "confirm": ("sweep3d.followups.confirm.run", "confirm"),
    "mark": ("sweep3d.followups.confirm.record", "mark"),
    "read_verdicts": ("sweep3d.followups.confirm.record", "read_verdicts"),
    "region_key": ("sweep3d.followups.confirm.claims", "region_key"),
    "rule_key": ("sweep3d.followups.confirm.claims", "rule_key"),
})
