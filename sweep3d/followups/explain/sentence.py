"""The sentence of one fix, written from its ``counterfactuals`` row, so that the stored
``sentence`` column, the console and the report's *Nearest fixes* panel say the same thing:

    +14 orientation_yaw makes it a toaster (margin +0.31; nearest to within 1/64 of the range:
    orientation_yaw 5.62)

It states what a user needs to trust the fix: the margin at the fix (the true class's probability
less the best other's), whether the stability check's rule calls it fragile (and what the search
did about it: see :mod:`.further`), and the search's resolution, in each parameter's own units,
which is what "nearest" means (the bisection stops when a wrong and a right probe are that close).
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any, Mapping, Sequence


def move_words(parameter: str, before: str, after: str, delta: float | None) -> str:
    """``+14 orientation_yaw`` for a number, ``camera_lens wide → tele`` for an option."""
    if delta is None:
        return f"{parameter} {before} → {after}"
    return f"{delta:+.3g} {parameter}"


def change_words(row: Mapping[str, Any]) -> str:
    """The moves of a row's fix: ``+14 orientation_yaw and camera_lens wide → tele``."""
    return " and ".join(move_words(p, a, b, d) for p, a, b, d in
                        zip(row["parameters"], row["from_values"], row["to_values"], row["deltas"]))


def share_words(resolution: float) -> str:
    """``1/64`` for a resolution that is one over a whole number, else ``0.02``."""
    fraction = Fraction(resolution).limit_denominator(4096)
    if fraction.numerator == 1 and abs(float(fraction) - resolution) < 1e-12:
        return f"1/{fraction.denominator}"
    return f"{resolution:.3g}"


def resolution_words(resolution: float | None, parameters: Sequence[str],
                     resolutions: Sequence[float | None] | None) -> str | None:
    """``nearest to within 1/64 of the range: orientation_yaw 5.62`` (each changed range, in its own
    units); None when only list options changed (an option is exact) or the resolution is unknown."""
    if resolution is None or not resolutions:
        return None
    ranged = [(p, r) for p, r in zip(parameters, resolutions) if r is not None]
    if not ranged:
        return None
    each = "the range" if len(ranged) == 1 else "each range"
    return f"nearest to within {share_words(resolution)} of {each}: " + ", ".join(f"{p} {r:.3g}" for p, r in ranged)


def trust_words(row: Mapping[str, Any]) -> str:
    """The margin and fragility of a row's fix, and what the search did about a fragile one:
    ``margin +0.31, not fragile``; ``fragile: margin +0.012, below the stability check's 0.05, and
    none of 6 probes further along the change clears it``; or, where a sturdier fix replaced the
    nearest, ``margin +0.21, not fragile; the nearest fix, +14 orientation_yaw at distance 0.039, is
    fragile: margin +0.012, below the stability check's 0.05; this is the first not fragile of 3
    probes past it (1/64 of the range, then doubling)``. Without a stability check, the margin alone."""
    threshold = row.get("fragile_threshold")
    said = _margin(row.get("fix_margin"))
    nearest = row.get("nearest_distance")
    if nearest is not None:  # a sturdier fix further along replaced the fragile nearest one
        probes = row.get("further_probes") or 0
        step = share_words(row["resolution"]) if row.get("resolution") is not None else "a search step"
        where = (f"this is one search step ({step} of the range) past it" if probes == 1 else
                 f"this is the first not fragile of {probes} probes past it ({step} of the range, then doubling)")
        return (f"{said}, not fragile; the nearest fix, {row.get('nearest_change') or 'unknown'} at distance "
                f"{nearest:.3g}, is fragile: {_margin(row.get('nearest_margin'))}, "
                f"{_why(row.get('nearest_margin'), threshold)}; {where}")
    if row.get("fix_fragile") is True:
        probes = row.get("further_probes") or 0
        stopped = row.get("complete", True) is False
        if probes:
            then = (f"and none of {probes} {'probe' if probes == 1 else 'probes'} further along the change clears it"
                    + (" before the budget ended" if stopped else ""))
        elif stopped:
            then = "and the budget ended before the search could go further"
        elif any(r is not None for r in row.get("resolutions") or ()):
            then = "at the end of the range"
        else:
            then = "and it changes list options only: nothing lies further along it"
        return f"fragile: {said}, {_why(row.get('fix_margin'), threshold)}, {then}"
    if row.get("fix_fragile") is False:
        return f"{said}, not fragile"
    return said


def _margin(value: float | None) -> str:
    return f"margin {value:+.3g}" if value is not None else "no margin"


def _why(margin: float | None, threshold: float | None) -> str:
    """Why the stability check's rule calls a verdict fragile: its margin, or its image flipped."""
    if threshold is not None and margin is not None and abs(margin) < threshold:
        return f"below the stability check's {threshold:.3g}"
    return "its image flipped in the stability check"


def fix_sentence(row: Mapping[str, Any]) -> str | None:
    """The whole sentence of a row's fix (None when none was found): the change, what the model says
    there, the margin and fragility, and (for the nearest fix) the search's resolution."""
    if not row.get("found"):
        return None
    label = row.get("fix_label") or row.get("true_labels") or "right"
    notes = [trust_words(row)]
    if row.get("nearest_distance") is None:  # a fix past the nearest says its own steps
        resolution = resolution_words(row.get("resolution"), row.get("parameters") or (), row.get("resolutions"))
        notes += [resolution] if resolution else []
    return f"{change_words(row)} makes it a {label} ({'; '.join(notes)})"
