"""What ``sweep3d confirm`` prints: each finding's verdict on fresh renders, and the test."""

from __future__ import annotations

from rich.console import Console
from rich.markup import escape

from sweep3d.confirm import ConfirmResult
from sweep3d.results import ALPHA, CONFIRMED


def print_confirmation(console: Console, result: ConfirmResult) -> None:
    if not result.confirmations:
        console.print("no significant finding to confirm: the run names no failure mode and no boundary")
        return
    for x in result.confirmations:
        v = x.verdict
        style = "green" if v.status == CONFIRMED else "yellow"
        if not v.pairs:
            console.print(f"[{style}]{v.status}[/]: {escape(x.claim.text)}: no fresh pair could be drawn and "
                          "predicted (every configuration of its region is a discovery job, out of frame or "
                          "not evaluable)", soft_wrap=True)
            continue
        console.print(
            f"[{style}]{v.status}[/]: {escape(x.claim.text)}: fresh accuracy {v.accuracy_inside:.0%} inside against "
            f"{v.accuracy_outside:.0%} outside on {v.pairs} twin pairs ({100 * v.difference:+.1f} pts, 95% CI "
            f"{100 * v.difference_low:+.1f} to {100 * v.difference_high:+.1f}); {v.inside_wrong} pairs wrong only "
            f"inside, {v.inside_right} only outside; p = {v.p_value:.2g}, Holm p = {v.p_holm:.2g}", soft_wrap=True)
    n = len(result.confirmations)
    console.print(
        f"fresh jobs: {result.jobs}, renders {result.rendered} made and {result.cached} cached (experiment "
        f"{escape(result.experiment)}); "
        "twins matched on every other parameter, none an image of the run; test: McNemar's exact, one-sided, on the "
        f"fresh pairs only, Holm-adjusted over the {n} finding{'s' * (n != 1)}: at most a {ALPHA:.0%} chance that "
        "any finding without a real effect is called confirmed", soft_wrap=True)
    if result.failed:
        console.print(f"[red]{result.failed} fresh jobs failed[/]; their pairs are left out")
