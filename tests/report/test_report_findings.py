"""The report's first screen: the findings list leads with each finding's grade (from the
``findings`` view), a click on a finding filters the explorer to its region, and the page before
any click is about three screens tall at 1,400 px.

The store is synthetic (``benchmarks/report_scale.py``: 2,000 results with failure modes,
boundaries and boxes); its findings are listed and graded as ``sweep3d grade`` would write them, a
different grade for each, so the order on the page is checked against the view's.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import sweep3d
from sweep3d.report import write_report
from sweep3d.report.panels.findings import region
from sweep3d.report.reading import materialise_views
from sweep3d.results import (
    BOUNDARY,
    BOX,
    FAILURE_MODE,
    FINDINGS_SCHEMA,
    FINDINGS_TABLE,
    GRADES,
    Finding,
    connect,
    grade_row,
    listed_findings,
    numeric_scales,
    record_listing,
    register_failure_boundaries,
    results_store,
    stored_rows,
    summarise,
)
from tests.helpers import ARTIFACTS, assert_clean, build_store, open_page

RESULTS = 2_000
WIDTH = 1_400
FIRST_SCREENS = 3_000  # px: the page before any click (the quickstart's was 12,018 with every panel open)


def grade_everything(spec: Path) -> list[tuple[str, str]]:
    """List the run's findings as ``run`` does and grade each (cycling through the grades), as
    ``sweep3d grade`` writes them; returns (text, grade) in the view's order."""
    loaded = sweep3d.load(spec).spec
    with results_store(loaded) as store:
        con = connect(store, loaded.name)
        try:
            materialise_views(con)
            scales = numeric_scales(loaded.controls)
            register_failure_boundaries(con, scales)
            findings = listed_findings(summarise(con, loaded.parameter_columns, scales=scales))
        finally:
            con.close()
        model = loaded.model.label
        listing = record_listing(store, loaded.name, model, findings, spec)
        listed_at = stored_rows(store, loaded.name, model)[0]["listed_at"]
        rows = [grade_row(loaded.name, model, listing, listed_at, f, GRADES[i % len(GRADES)], f"evidence {i}",
                          pairs=40, effect=-0.3, effect_low=-0.5, effect_high=-0.1)
                for i, f in enumerate(findings)]
        store.append(FINDINGS_TABLE, rows, FINDINGS_SCHEMA)
    return [(f.text, GRADES[i % len(GRADES)]) for i, f in enumerate(findings)]


@pytest.fixture(scope="module")
def graded(tmp_path_factory) -> tuple[Path, list[tuple[str, str]]]:
    spec = build_store(tmp_path_factory.mktemp("findings") / "run", RESULTS)
    grades = grade_everything(spec)
    return write_report(sweep3d.load(spec).spec), grades


LEVELS = {"object": [(0, "mug", None), (1, "toaster", None)],
          "blur_sigma": [(0, "0", 0.0), (1, "1", 1.0), (2, "2", 2.0), (3, "3", 3.0)],
          "orientation_yaw": [(i, f"{lo}–{lo + 36}", lo + 18.0) for i, lo in enumerate(range(-180, 180, 36))]}


def test_a_findings_region_is_its_levels_on_the_explorers_axes() -> None:
    mode = Finding("value object = toaster", FAILURE_MODE, "object = toaster", 0, {"column": "object", "label": "toaster"})
    assert region(mode, LEVELS) == [["object", [1]]]
    boundary = Finding("b", BOUNDARY, "", 1, {"parameter": "blur_sigma", "scope": "object", "object": "mug",
                                              "fails": "above", "boundary": 1.5})
    assert region(boundary, LEVELS) == [["blur_sigma", [2, 3]], ["object", [0]]]
    below = Finding("b", BOUNDARY, "", 1, {"parameter": "blur_sigma", "scope": "all", "fails": "below", "boundary": 2})
    assert region(below, LEVELS) == [["blur_sigma", [0, 1]]]  # the boundary itself is on neither side
    box = Finding("r", BOX, "", 2, {"conditions": [{"column": "blur_sigma", "value": 3.0, "low": None, "high": None},
                                                   {"column": "orientation_yaw", "value": None, "low": 0.0,
                                                    "high": 72.0}]})
    assert region(box, LEVELS) == [["blur_sigma", [3]], ["orientation_yaw", [5, 6]]]  # bins by their middles
    unknown = Finding("value x = 1", FAILURE_MODE, "x = 1", 0, {"column": "x", "label": "1"})
    assert region(unknown, LEVELS) == []  # nothing to filter by: the line is not clickable


@pytest.mark.browser
def test_the_findings_lead_with_their_grades_on_a_page_of_three_screens(graded, chromium) -> None:
    path, grades = graded
    assert len({g for _, g in grades}) > 1, grades  # the order of the grades is checked, not one grade
    with open_page(chromium, path, width=WIDTH, unfold=False) as (page, events):
        first = page.evaluate("Array.from(document.querySelectorAll('main > section')).map(s => s.id).slice(0, 2)")
        assert first == ["findings", "explorer"]
        lines = page.evaluate("""Array.from(document.querySelectorAll('#findings-list > li')).map(li => [
            li.firstElementChild.className, li.firstElementChild.textContent.trim(),
            li.querySelector('.finding-text').lastChild.textContent.trim()])""")
        assert [(text, grade) for _, grade, text in lines] == grades
        assert all(cls.split()[0] == "grade" for cls, _, _ in lines)
        height = page.evaluate("document.documentElement.scrollHeight")
        assert height <= FIRST_SCREENS, height
        assert page.evaluate("document.documentElement.scrollWidth") == WIDTH  # nothing runs off the side
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "findings-first-screen.png"))
        assert_clean(path, events)


@pytest.mark.browser
def test_clicking_a_finding_filters_the_explorer_to_its_region(graded, chromium) -> None:
    path, _ = graded
    spec = sweep3d.load(path.parent.parent.parent / "spec.toml").spec
    with open_page(chromium, path, width=WIDTH, unfold=False) as (page, events):
        findings = page.evaluate("Array.from(document.querySelectorAll('#findings-list > li:not(.no-region)'))"
                                 ".map(li => [li.dataset.text, JSON.parse(li.dataset.region)])")
        assert findings
        for index in {0, len(findings) - 1}:  # a failure mode first, a box or boundary last
            text, terms = findings[index]
            page.locator("#findings-list > li:not(.no-region)").nth(index).click()
            page.wait_for_function("t => document.querySelector('#explorer-gallery h3')?.textContent.startsWith(t)",
                                   arg=text)
            where = " AND ".join(f"job IN (SELECT job FROM control_levels WHERE parameter = '{name}' "
                                 f"AND list_contains({levels}, level))" for name, levels in terms)
            with results_store(spec) as store:
                con = connect(store, spec.name)
                counted = con.execute(f"SELECT count(*) FROM results WHERE counted AND {where}").fetchone()[0]
                con.close()
            status = page.inner_text("#explorer-status")
            assert status.startswith(f"{counted} valid results in the finding's region"), (status, counted)
            labels = {name: page.evaluate(
                "n => JSON.parse(document.getElementById('explorer-data').textContent).params"
                ".find(p => p.name === n).labels", name) for name, _ in terms}
            titles = page.evaluate("Array.from(document.querySelectorAll('#explorer-gallery .tile')).map(t => t.title)")
            assert titles, text
            for title in titles:  # every image shown is inside the region
                assert all(any(f"{name} = {labels[name][level]} " in title + " " for level in levels)
                           for name, levels in terms), (title, terms)
        page.click(".region-bar button")
        assert "match the sliders" in page.inner_text("#explorer-status")
        assert_clean(path, events)
