"""What ``sweep3d confirm`` prints: each finding's verdict on fresh renders, and the test."""

from __future__ import annotations

from rich.console import Console
from rich.markup import escape

from sweep3d.followups.confirm import ConfirmResult
from sweep3d.results import ALPHA, CONFIRMED, pairs_needed, renders_for


def print_confirmation(console: Console, result: ConfirmResult) -> None:
    if not result.confirmations:
        console.print("no significant finding to confirm: the run names no failure mode and no boundary")
        return
    tested = sum(x.verdict.pairs > 0 for x in result.confirmations)
    needed = pairs_needed(tested)
    for x in result.confirmations:
        v = x.verdict
        style = "green" if v.status == CONFIRMED else "yellow"
        if 0 < v.pairs < needed:  # the advice counts the pairs kept of those --renders drew (some are dropped)
            console.print(f"[{style}]{v.status}[/]: {escape(x.claim.text)}: {v.pairs} fresh pairs are too few for any "
                          f"outcome to confirm it among {tested} findings ({needed} at least; --renders "
                          f"{renders_for(needed, v.pairs, result.renders)} or more)", soft_wrap=True)
            continue
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
    fewest = min((x.verdict.pairs for x in result.confirmations if x.verdict.pairs), default=0)
    if 0 < fewest < 2 * needed:
        console.print(f"[dim]few pairs: with {fewest} pairs a finding is confirmed only if nearly all of its "
                      f"discordant pairs go its way, so 'not replicated' says little; --renders "
                      f"{renders_for(2 * needed, fewest, result.renders)} "
                      "or more for power[/]", soft_wrap=True)
    console.print(
        f"fresh jobs: {result.jobs}, renders {result.rendered} made and {result.cached} cached (experiment "
        f"{escape(result.experiment)}); "
        "twins matched on every other parameter, none an image of the run; test: McNemar's exact, one-sided, on the "
        f"fresh pairs only, Holm-adjusted over the {n} finding{'s' * (n != 1)}: at most a {ALPHA:.0%} chance that "
        "any finding without a real effect is called confirmed", soft_wrap=True)
    if result.failed:
        console.print(f"[red]{result.failed} fresh jobs failed[/]; their pairs are left out")
