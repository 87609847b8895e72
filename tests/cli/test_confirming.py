"""What ``sweep3d confirm`` prints (:mod:`sweep3d.cli.confirming`), from a result made here: nothing
is rendered."""

from __future__ import annotations

import io

from rich.console import Console

from sweep3d.cli.confirming import print_confirmation
from sweep3d.followups.confirm.claims import boundary_claim
from sweep3d.followups.confirm.run import Confirmation, ConfirmResult
from sweep3d.results.confirmation import Pairs, judge, pairs_needed
from sweep3d.spec.params import Range


def test_confirm_advises_more_renders_than_were_given_when_pairs_were_dropped() -> None:
    """The audit's case: --renders 16 kept 6 pairs (two dropped as hidden) where 7 are needed among
    five findings; it advised "--renders 14 or more". (Six pairs all one way confirm a finding
    among three: Holm's family is then the first three, and the two left out need 7 to join.)"""
    assert pairs_needed(5) == 7 and pairs_needed(3) == 6 and pairs_needed(4) == 7
    verdicts = judge([Pairs(inside_wrong=6)] * 5)
    assert [v.status for v in verdicts] == ["confirmed"] * 3 + ["unconfirmed"] * 2
    row = {"parameter": "blur_sigma", "scope": "all", "object": None, "environment": None, "fails": "above",
           "boundary": 1.5, "values": 4, "boundary_low": 1.0, "boundary_high": 2.0}
    claim = boundary_claim(row, "blur_sigma fails above 1.5", Range(0.0, 3.0))
    result = ConfirmResult("e-confirm", [Confirmation(claim, 6, v) for v in verdicts], 60, 60, 0, 0, renders=16)
    out = io.StringIO()
    print_confirmation(Console(file=out, width=400), result)
    advice = [line for line in out.getvalue().splitlines() if "too few" in line]
    assert len(advice) == 2 and all("(7 at least; --renders 20 or more)" in line for line in advice), advice
    assert not [line for line in out.getvalue().splitlines() if line.startswith("few pairs")]
