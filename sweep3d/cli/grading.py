"""What ``sweep3d grade`` prints: each finding's grade and its evidence, then what the checks cost."""

from __future__ import annotations

from collections import Counter

from rich.console import Console
from rich.markup import escape

from sweep3d.followups.grade import Graded
from sweep3d.results import GRADES

#: Each grade's colour in the console (the report uses the same order).
GRADE_STYLE = {"solid": "green", "renderer-sensitive": "magenta", "fragile": "yellow", "not replicated": "red",
               "inconclusive": "cyan", "untested": "dim"}


def print_grades(console: Console, graded: Graded, spec_path: object) -> None:
    if not graded.findings:
        console.print("no finding to grade: the run names no failure mode, boundary or box")
        return
    for finding, (grade, evidence) in zip(graded.findings, graded.grades):
        console.print(f"[{GRADE_STYLE[grade]}]{grade}[/]: {escape(finding.text)} ({finding.kind}): {escape(evidence)}",
                      soft_wrap=True, highlight=False)
    counts = Counter(g for g, _ in graded.grades)
    console.print("grades: " + ", ".join(f"{counts[g]} {g}" for g in GRADES if counts[g]), highlight=False)
    checked = graded.stability
    if checked is not None:
        low, high = checked.fragile_range
        fragile = (f"{checked.fragile_failures} of {checked.failures} failures fragile" +
                   (f" (between {low} and {high} as the undecided margin bins fall)" if high > low else ""))
        scene = ("" if graded.scene_budget is None else
                 f"; the image changes only: the scene neighbours need --budget {graded.scene_budget} at least")
        console.print(f"stability: {checked.sampled} images checked; {fragile}; threshold |margin| < "
                      f"{checked.threshold:.3g}{scene}", highlight=False, soft_wrap=True)
    if counts["inconclusive"] and graded.used >= graded.budget // 2:
        doubled = 2 * max(graded.budget, 1)
        why = ("about what gives each of them the pairs that could confirm it" if graded.wanted > doubled else
               "a second look at these pairs, each look at 5 %")
        console.print(f"{counts['inconclusive']} inconclusive: a larger budget goes on from here, reusing the renders made "
                      f"(sweep3d grade {escape(str(spec_path))} --budget {max(doubled, graded.wanted)}; {why})",
                      highlight=False, soft_wrap=True)
    if graded.replaced is not None:
        console.print(f"note: these grades replace those of --budget {graded.replaced} (more renders); "
                      f"sweep3d grade {escape(str(spec_path))} --budget {graded.replaced} gives them back, every "
                      "render cached", highlight=False, soft_wrap=True)
    console.print(f"{graded.used} renders of the budget's {graded.budget} used ({graded.rendered} rendered now); "
                  f"second renderer {graded.engine}; {graded.seconds:.0f} s. The grades are the `findings` view "
                  f"(sweep3d query {escape(str(spec_path))} \"SELECT * FROM findings\") and lead the report",
                  soft_wrap=True, highlight=False)
