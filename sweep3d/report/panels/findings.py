"""Findings: the page's first answer, where the model fails and which of those findings to trust.

Every finding the run names (failure modes, boundaries, boxes: :func:`~sweep3d.results.listed_findings`,
the boundaries the console leaves to the report included) is one line, leading with its grade
from the ``findings`` view (``sweep3d grade``; *untested* until then, and a finding the view does
not list yet is shown untested, never left out), then its text, the run's effect and one line of
evidence; the full evidence (fresh pairs, second renderer, fragile verdicts set aside, and what
``sweep3d confirm`` recorded) is a click away.

Each line carries its *region* on the explorer's levels, so that clicking it filters the
explorer's counts and images to it (as a slice list does in Zeno): a failure mode's value, a
boundary's failing side (and its object or environment), a box's conditions. A level is inside
when its value is (a bin: when its middle is), so a region cut inside a bin is shown by whole bins.
"""

from __future__ import annotations

from typing import Any, Mapping

from sweep3d.followups.confirm import read_verdicts
from sweep3d.report.panel import PanelInputs
from sweep3d.report.panels.confirmations import verdict_row
from sweep3d.report.reading import level_values, read_grades
from sweep3d.results import BOUNDARY, BOX, GRADES, UNTESTED, Finding, listed_findings, not_graded

Levels = Mapping[str, list[tuple[int, str, float | None]]]


def build(inputs: PanelInputs) -> dict[str, Any]:
    """One row per finding, in the order ``run`` prints them, and how many of each grade."""
    graded = read_grades(inputs.con, _model(inputs))
    verdicts = read_verdicts(inputs.store, inputs.loaded.name)
    levels = level_values(inputs.con)
    rows = [_row(f, graded.get(f.key), verdicts.get(f.key), levels, inputs.loaded.path)
            for f in listed_findings(inputs.summary)]
    counts = [(g, sum(r["grade"] == g for r in rows)) for g in GRADES]
    return {"rows": rows, "counts": [(g, n) for g, n in counts if n], "confirmed": bool(verdicts),
            "graded": any(r["grade"] != UNTESTED for r in rows), "spec": str(inputs.loaded.path)}


def _model(inputs: PanelInputs) -> str:
    """The model the page shows: its results' (``results.connect`` was given it), else the spec's first."""
    if any(row[0] == "model" for row in inputs.con.execute("DESCRIBE results").fetchall()):
        found = inputs.con.execute("SELECT any_value(model) FROM results").fetchone()[0]
        if found is not None:
            return str(found)
    return inputs.loaded.model.label


def _row(finding: Finding, graded: Mapping[str, Any] | None, confirmed: Mapping[str, Any] | None,
         levels: Levels, spec: Any) -> dict[str, Any]:
    """A finding's line: grade, text, the run's effect, evidence, the checks' numbers, its region."""
    grade = graded["grade"] if graded else UNTESTED
    evidence = graded["evidence"] if graded else not_graded(spec)
    details = []
    if graded and graded.get("pairs"):
        details.append(f"fresh renders: {_points(graded['effect'])} points on {graded['pairs']} pairs "
                       f"(interval {_points(graded['effect_low'])} to {_points(graded['effect_high'])})")
    if graded and graded.get("engine_pairs"):
        details.append(f"second renderer ({graded['engine']}): {_points(graded['engine_effect'])} points on "
                       f"{graded['engine_pairs']} pairs")
    if graded and graded.get("fragile_set_aside"):
        details.append(f"{graded['fragile_set_aside']} fresh wrong verdicts set aside as fragile")
    return {
        "grade": grade, "grade_class": "grade-" + grade.replace(" ", "-"), "kind": finding.kind,
        "text": finding.text, "effect": _points(finding.run_difference), "evidence": evidence, "details": details,
        "confirm": verdict_row(confirmed) if confirmed else None, "region": region(finding, levels),
    }


def _points(difference: float | None) -> str:
    return "–" if difference is None else f"{100 * difference:+.0f}".replace("-", "−")


def region(finding: Finding, levels: Levels) -> list[list[Any]]:
    """The finding's region as ``[[parameter, [level, …]], …]`` on the explorer's levels ([] when
    none of its parameters has levels)."""
    source = finding.source
    if finding.kind == BOUNDARY:
        side = (lambda v: v < source["boundary"]) if source["fails"] == "below" else (lambda v: v > source["boundary"])
        terms = [(source["parameter"], lambda label, value: value is not None and side(value))]
        if source["scope"] != "all":
            terms.append((source["scope"], _equal(source[source["scope"]])))
    elif finding.kind == BOX:
        terms = [(c["column"], _condition(c)) for c in source["conditions"]]
    else:
        terms = [(source["column"], _equal(source["label"]))]
    out = []
    for name, inside in terms:
        found = [level for level, label, value in levels.get(name, []) if inside(label, value)]
        if found:
            out.append([name, found])
    return out


def _equal(wanted: Any):
    """A level test for ``parameter = wanted`` (a number compared by value, a name by its label)."""
    if isinstance(wanted, (int, float)) and not isinstance(wanted, bool):
        return lambda label, value: value is not None and abs(value - float(wanted)) < 1e-9
    return lambda label, value: label == str(wanted)


def _condition(condition: Mapping[str, Any]):
    """A level test for a box's condition: ``column = value``, or its value in (low, high]."""
    if condition.get("value") is not None:
        return _equal(condition["value"])
    low, high = condition.get("low"), condition.get("high")
    return lambda label, value: (value is not None and (low is None or value > low)
                                 and (high is None or value <= high))

