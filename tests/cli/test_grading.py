"""What ``sweep3d grade`` prints after its grades: the cost, and where the budget left findings
inconclusive, the command that goes on from there."""

from __future__ import annotations

from rich.console import Console

from sweep3d.cli.grading import print_grades
from sweep3d.followups.grade import Graded
from sweep3d.results import Finding


def _printed(grades: list[tuple[str, str]], used: int, budget: int) -> str:
    findings = [Finding(f"k{i}", "boundary", f"[b]finding {i}[/b]", i, {}) for i in range(len(grades))]
    console = Console(record=True, width=300)
    print_grades(console, Graded(findings, grades, budget, used, 7, 1.0, "mitsuba"), "my [spec].toml")
    return console.export_text()


def test_inconclusive_findings_after_a_spent_budget_name_the_budget_that_goes_on() -> None:
    text = _printed([("solid", "replicated"), ("inconclusive", "the budget ended")], used=470, budget=480)
    assert "1 inconclusive: a larger budget goes on from here" in text
    assert "sweep3d grade my [spec].toml --budget 960" in text  # the path as text, not markup
    assert "[b]finding 1[/b]" in text and "470 renders of the budget's 480 used (7 rendered now)" in text


def test_no_advice_when_nothing_is_inconclusive_or_the_budget_was_not_what_stopped_it() -> None:
    assert "larger budget" not in _printed([("solid", "replicated")], used=470, budget=480)
    assert "larger budget" not in _printed([("inconclusive", "mitsuba did not decide")], used=10, budget=480)


def test_a_budget_too_small_for_the_scene_neighbours_says_which_budget_renders_them() -> None:
    from types import SimpleNamespace

    checked = SimpleNamespace(fragile_range=(3, 9), fragile_failures=3, failures=10, sampled=64, threshold=0.05)
    findings = [Finding("k0", "boundary", "finding 0", 0, {})]

    def printed(scene_budget: int | None) -> str:
        console = Console(record=True, width=300)
        print_grades(console, Graded(findings, [("solid", "replicated")], 160, 150, 7, 1.0, "mitsuba", checked,
                                     scene_budget=scene_budget), "spec.toml")
        return console.export_text()

    assert "the image changes only: the scene neighbours need --budget 256 at least" in printed(256)
    assert "stability: 64 images checked" in printed(None) and "image changes only" not in printed(None)


def test_a_smaller_budget_says_whose_grades_it_replaced_and_how_to_get_them_back() -> None:
    import json

    from sweep3d.followups.grade.run import larger_budget

    def row(budget: int, seed: int = 0, listing: str = "L") -> dict:
        return {"listing": listing, "details": json.dumps({"budget": budget, "seed": seed})}

    assert larger_budget([row(160), row(160)], "L", 2, 0) == 160
    assert larger_budget([row(160)], "L", 320, 0) is None  # a larger one replaces nothing it had
    assert larger_budget([row(160, seed=1), row(160, listing="M"), {"listing": "L", "details": None}], "L", 2, 0) \
        is None  # another seed's pairs, another listing, a row from before budgets were recorded
    findings = [Finding("k0", "boundary", "finding 0", 0, {})]
    console = Console(record=True, width=300)
    print_grades(console, Graded(findings, [("inconclusive", "x")], 2, 2, 0, 1.0, "mitsuba", replaced=160), "s.toml")
    assert "these grades replace those of --budget 160 (more renders); sweep3d grade s.toml --budget 160" in \
        console.export_text()


def test_findings_short_of_the_pairs_that_could_confirm_them_are_advised_the_budget_that_gives_them() -> None:
    from types import SimpleNamespace

    from sweep3d.followups.grade.run import REPLICATION_SHARE, wanted_budget
    from sweep3d.results import pairs_to_confirm

    short = [SimpleNamespace(pairs=pairs, findings=18, looks=1, in_family=pairs > 0) for pairs in (0, 1, 5)]
    missing = sum(pairs_to_confirm(v) - v.pairs for v in short)
    wanted = wanted_budget(short, stability_used=16, replication_used=8)

    def replication_share(budget: int) -> int:  # what grade gives the replication of a budget
        return int((budget - 16) * REPLICATION_SHARE)

    assert replication_share(wanted) >= 8 + 2 * missing > replication_share(wanted - 1)  # the least that is enough
    assert wanted_budget([], 16, 8) == 0
    findings = [Finding(f"k{i}", "boundary", f"finding {i}", i, {}) for i in range(3)]
    console = Console(record=True, width=300)
    print_grades(console, Graded(findings, [("inconclusive", "x")] * 3, 8, 8, 8, 1.0, "mitsuba", wanted=wanted),
                 "s.toml")
    assert (f"--budget {wanted}; about what gives each of them the pairs that could confirm it"
            in console.export_text())
