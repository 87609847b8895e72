"""``sweep3d stability``: run the check and print what it found (see :mod:`sweep3d.followups.stability`)."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.table import Table


def run_stability(console: Console, spec_path: Path, sample: int, seed: int | None, wait: float = 0.0) -> None:
    """``seed``: None is the spec's ``[experiment] seed``, as ``explain`` and ``confirm`` take it;
    ``wait``: seconds to wait for another command holding the store's lock."""
    from sweep3d.api import Experiment
    from sweep3d.followups.stability import check_stability

    spec = Experiment(spec_path).spec
    seed = spec.experiment.seed if seed is None else seed
    for found in check_stability(spec, sample, seed, console, wait):
        which = f"{escape(found.model)}: " if len(spec.spec.all_models) > 1 else ""
        console.print(f"{which}stability check of {found.sampled} images ({found.cached} cached, {found.computed} "
                      f"inferred now; seed {seed})")
        for line in found.skipped:
            console.print(f"  not applied: {escape(line)}")
        table = Table("|margin|", "images", "flipped", "flip rate", "95% Wilson interval")
        for row in found.bins:
            if not row["n"]:
                continue
            close = "]" if row["upper"] >= 1.0 else ")"  # the last bin holds 1
            table.add_row(f"[{row['lower']:g}, {row['upper']:g}{close}", str(row["n"]), str(row["flips"]),
                          f"{row['flip_rate']:.0%}", f"{row['wilson_low']:.0%}–{row['wilson_high']:.0%}")
        console.print(table)
        by_change: dict[str, tuple[int, int]] = {}
        for row in found.changes:
            n, flips = by_change.get(row["change"], (0, 0))
            by_change[row["change"]] = (n + row["n"], flips + row["flips"])
        console.print("flips per change: " + ", ".join(f"{c} {f} of {n}" for c, (n, f) in by_change.items()))
        rule = (f"|margin| < {found.threshold:.3g} (bins where 1 in 10 checked images or more flip, beyond doubt: "
                "the lower end of the Wilson interval)" if found.threshold
                else "no margin bin where 1 in 10 checked images or more flip beyond doubt")
        console.print(f"{which}fragile: {rule}, or flipped in the check: {found.fragile_failures} of "
                      f"{found.failures} failures")
