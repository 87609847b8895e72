"""What ``sweep3d confirm`` prints: each finding's verdict on fresh renders, and the test."""

from __future__ import annotations

from rich.console import Console
from rich.markup import escape

from sweep3d.followups.confirm import ConfirmResult
from sweep3d.results import (
    ALPHA,
    CONFIRMED,
    FUTILITY,
    INCONCLUSIVE,
    UNCONFIRMED,
    Verdict,
    pairs_to_confirm,
    renders_for,
)


def print_confirmation(console: Console, result: ConfirmResult) -> None:
    if not result.confirmations:
        console.print("no significant finding to confirm: the run names no failure mode and no boundary")
        return
    looks = max((x.verdict.looks for x in result.confirmations), default=1)
    for x in result.confirmations:
        v = x.verdict
        style = "green" if v.status == CONFIRMED else "yellow"
        if v.pairs and v.status == UNCONFIRMED:  # too few; the advice counts the pairs kept of those drawn
            needed = pairs_to_confirm(v)
            console.print(f"[{style}]{v.status}[/]: {escape(x.claim.text)}: {v.pairs} fresh pairs are too few for any "
                          f"outcome to confirm it among the findings tested ({needed} at least; --renders "
                          f"{renders_for(needed, v.pairs, result.renders)} or more)", soft_wrap=True)
            continue
        if not v.pairs:
            console.print(f"[{style}]{v.status}[/]: {escape(x.claim.text)}: no fresh pair could be drawn and "
                          "predicted (every configuration of its region is a discovery job, out of frame or "
                          "not evaluable)", soft_wrap=True)
            continue
        console.print(f"[{style}]{v.status}[/]: {escape(confirmation_line(x.claim.text, v))}", soft_wrap=True)
    console.print(
        f"fresh jobs: {result.jobs}, renders {result.rendered} made and {result.cached} cached (experiment "
        f"{escape(result.experiment)}); "
        "twins matched on every other parameter, none an image of the run; test: McNemar's exact, one-sided, on the "
        "fresh pairs only, Holm-adjusted over the findings with pairs enough to be confirmed; "
        f"{looks_sentence(looks)}",
        soft_wrap=True)
    if result.failed:
        console.print(f"[red]{result.failed} fresh jobs failed[/]; their pairs are left out")


def confirmation_line(text: str, v: Verdict) -> str:
    """One finding's verdict with its effect and interval; an inconclusive one says what was not shown."""
    level = 1 - ALPHA / v.looks
    line = (f"{text}: fresh accuracy {v.accuracy_inside:.0%} inside against {v.accuracy_outside:.0%} outside on "
            f"{v.pairs} twin pairs ({100 * v.difference:+.1f} pts, {level:.1%} CI {100 * v.difference_low:+.1f} to "
            f"{100 * v.difference_high:+.1f}); {v.inside_wrong} pairs wrong only inside, {v.inside_right} only "
            f"outside; p = {v.p_value:.2g}, Holm p = {v.p_holm:.2g} (look {v.look} of at most {v.looks})")
    if v.status == INCONCLUSIVE:
        line += (f": neither confirmed nor bounded: the effect may be {100 * v.futility:.0f} points or more "
                 "(--max-renders for more pairs)")
    elif v.status != CONFIRMED and v.difference_low is not None and v.difference_low > -v.futility:
        line += f": the region costs less than {100 * v.futility:.0f} points of accuracy, beyond doubt"
    return line


def looks_sentence(looks: int) -> str:
    """The error control over the looks."""
    if looks <= 1:
        share = f"at most a {ALPHA:.0%} chance that any finding without a real effect is called confirmed"
    else:
        share = (f"{ALPHA:.0%} spent evenly over at most {looks} looks (Bonferroni: {ALPHA / looks:.2%} each), so at "
                 f"most a {ALPHA:.0%} chance over all looks that any finding without a real effect is called confirmed")
    return (f"{share}; not replicated only when the effect is bounded below {100 * FUTILITY:.0f} points, "
            "otherwise inconclusive")
