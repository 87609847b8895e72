"""``sweep3d stability``: run the check and print what it found (see :mod:`sweep3d.followups.stability`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table


def run_stability(console: Console, spec_path: Path, sample: int, seed: int | None, wait: float = 0.0,
                  max_sample: int | None = None, scene: bool | None = None, executor: str = "local",
                  address: str | None = None) -> None:
    """``seed``: None is the spec's ``[experiment] seed``, as ``explain`` and ``confirm`` take it;
    ``wait``: seconds to wait for another command holding the store's lock; ``max_sample``: the
    sequential design's cap (None: one round of ``sample``); ``scene``: re-render the sampled jobs'
    neighbours (None: the spec's ``[stability] scene``); ``executor``, ``address``: where they render."""
    from sweep3d.api import EXECUTORS, Experiment
    from sweep3d.core import UserError
    from sweep3d.followups.stability import check_stability
    from sweep3d.stages.render import Executor

    if executor not in EXECUTORS:
        raise UserError(f"--executor {executor}: use local or ray")
    spec = Experiment(spec_path).spec
    seed = spec.experiment.seed if seed is None else seed
    for found in check_stability(spec, sample, seed, console, wait, executor=Executor(executor, address),
                                 max_sample=max_sample, scene=scene):
        which = f"{escape(found.model)}: " if len(spec.spec.all_models) > 1 else ""
        console.print(f"{which}stability check of {found.sampled} images ({found.cached} cached, {found.computed} "
                      f"inferred now; seed {seed})")
        if found.rounds is not None:
            console.print(escape(stop_sentence(found, max_sample)))
        for line in found.skipped:
            console.print(f"  not applied: {escape(line)}")
        table = Table("|margin|", "images", "flipped", "flip rate", "95% Wilson interval", "decided")
        for index, row in enumerate(found.bins):
            if not row["n"]:
                continue
            close = "]" if row["upper"] >= 1.0 else ")"  # the last bin holds 1
            table.add_row(f"[{row['lower']:g}, {row['upper']:g}{close}", str(row["n"]), str(row["flips"]),
                          f"{row['flip_rate']:.0%}", f"{row['wilson_low']:.0%}–{row['wilson_high']:.0%}",
                          escape(decision_cell(found, index)))
        console.print(table)
        by_change: dict[str, tuple[int, int]] = {}
        for row in found.changes:
            n, flips = by_change.get(row["change"], (0, 0))
            by_change[row["change"]] = (n + row["n"], flips + row["flips"])
        console.print("flips per change: " + escape(", ".join(f"{c} {f} of {n}" for c, (n, f) in by_change.items())))
        for line in scene_lines(found):
            console.print(f"{which}{escape(line)}")
        console.print(f"{which}{escape(fragile_count_sentence(found))}")


def scene_lines(found: Any) -> list[str]:
    """What the scene neighbours cost and found: the neighbours, the parameters not moved, and
    worst-of-neighbourhood accuracy beside plain accuracy, over all objects and per object."""
    check = found.scene
    if check is None:
        return ["scene neighbours: not checked (--no-scene, or [stability] scene = false)"]
    lines = [f"  not moved: {line}" for line in check.skipped_lines()]
    if not check.moves:
        return ["scene neighbours: none (no varied rendered parameter has an invisible step)", *lines]
    moved = ", ".join(f"{m.label} ±{m.size * 100:g}%" if m.kind in ("distance", "closeness", "light")
                      else f"{m.label} ±{m.size:g}°" for m in check.moves)
    left = [f"{check.out_of_frame} out of frame"] if check.out_of_frame else []
    left += [f"{check.no_verdict} without a verdict to compare"] if check.no_verdict else []
    failed = f", {check.failed} failed" if check.failed else ""
    lines.insert(0, f"scene neighbours ({moved}): {len(check.planned)} of the sampled images' neighbours, "
                    f"{check.cached} compared before, {check.computed} now ({check.rendered} renders made{failed})"
                    + (f"; {', '.join(left)}" if left else ""))
    rows = found.neighbourhood
    overall = next((r for r in rows if r["object"] is None), None)
    if overall is None or not overall["images"]:
        return [*lines, "worst-of-neighbourhood accuracy: no sampled image has a neighbour compared yet"]
    lines.append(f"worst-of-neighbourhood accuracy (correct only if the image and every neighbour is): "
                 f"{_accuracy(overall)} over {overall['images']} sampled images; "
                 f"{overall['flipped']} flipped under a neighbour")
    lines += [f"  {row['object']}: {_accuracy(row)} over {row['images']}" for row in rows if row["object"] is not None]
    return lines


def _accuracy(row: dict[str, Any]) -> str:
    return (f"{row['worst_accuracy']:.0%} ({row['worst_low']:.0%}–{row['worst_high']:.0%}) against "
            f"{row['accuracy']:.0%} plain ({row['accuracy_low']:.0%}–{row['accuracy_high']:.0%})")


def stop_sentence(found: Any, max_sample: int | None) -> str:
    """Where the sequential check stopped, and the error control over its looks."""
    from sweep3d.followups.stability import ALPHA, look_z

    rounds = found.rounds
    why = {"decided": "every margin bin decided against the rule",
           "exhausted": "no undecided margin bin has images left in the run",
           "cap": f"the cap (--max-sample {max_sample}) reached with {_bins(len(rounds.undecided()))} undecided"}
    level = 1 - ALPHA / rounds.looks
    return (f"stopped at {rounds.sample} images after {rounds.rounds} of at most {rounds.looks} rounds: "
            f"{why[rounds.stopped]} (each bin decided by its Wilson interval at {level:.2%} (z = "
            f"{look_z(rounds.looks):.2f}): {ALPHA:.0%} split over the {rounds.looks} planned looks, Bonferroni, so "
            f"a bin is decided the wrong way with probability at most {ALPHA:.0%})")


def decision_cell(found: Any, index: int) -> str:
    """A bin's decision, and for an undecided one the sample that would decide it."""
    from sweep3d.followups.stability import UNDECIDED, needed

    if found.rounds is None or index >= len(found.rounds.decisions):
        return ""
    decision = found.rounds.decisions[index][0]
    if decision != UNDECIDED:
        return decision
    row = found.bins[index]
    more = needed(int(row["flips"]), int(row["n"]), found.rounds.looks)
    if not more:
        return "undecided: its flip rate is too near 1 in 10 for any sample to decide"
    pools = found.rounds.pools
    have = pools[index] if index < len(pools) else None
    short = f"; the run has {have}: a larger sweep would" if have is not None and more > have else ""
    return f"undecided: about {more} images of the bin would decide it at its flip rate{short}"


def fragile_count_sentence(found: Any) -> str:
    """The fragile count, with its interval: a lower bound when bins remain undecided."""
    from sweep3d.results import FLIP_RATE

    share = f"1 in {round(1 / FLIP_RATE)}"
    rule = (f"|margin| < {found.threshold:.3g} (bins where {share} checked images or more flip, beyond doubt: "
            "the lower end of the Wilson interval)" if found.threshold
            else f"no margin bin where {share} checked images or more flip beyond doubt")
    if found.rounds is None or not found.rounds.undecided():
        decided = "" if found.rounds is None else "; every margin bin decided"
        return f"fragile: {rule}, or flipped in the check: {found.fragile_failures} of {found.failures} failures{decided}"
    least, most = found.fragile_range
    low, high = found.threshold_range
    return (f"fragile: at least {least} of {found.failures} failures, a lower bound: {least} to {most} depending on "
            f"{_bins(len(found.rounds.undecided()))} still undecided (|margin| < {low:.3g} to < {high:.3g}, or "
            f"flipped in the check); {found.fragile_failures} by the rule as it reads now ({rule})")


def _bins(n: int) -> str:
    return f"{n} margin bin" if n == 1 else f"{n} margin bins"
