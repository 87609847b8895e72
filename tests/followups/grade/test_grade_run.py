"""``sweep3d grade`` end to end on a tiny real spec (32 px, one sample): a model that fails exactly
on dark images, so the run finds a brightness boundary; grading replicates it on fresh twins,
renders the same twins with Mitsuba, and writes a grade for every finding; a second grading with
the same budget renders nothing and gives the same grades; ``run`` then marks each finding."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.results import GRADES, SOLID, UNTESTED
from tests.helpers import load_spec, write_spec
from tests.helpers.planted import FRESH_SPEC as SPEC
from tests.helpers.planted import bright_spec

pytestmark = [pytest.mark.slow, pytest.mark.blender, pytest.mark.torch]


def _findings(spec: Path) -> list[tuple]:
    from sweep3d.api import Experiment

    return [tuple(r.values()) for r in Experiment(spec).sql(
        "SELECT finding, grade, evidence, pairs FROM findings ORDER BY rank").to_pylist()]


def test_grade_writes_a_grade_for_every_finding_and_a_rerun_renders_nothing(tmp_path: Path) -> None:
    from sweep3d.followups.grade import grade_findings

    spec = bright_spec(tmp_path)
    runner = CliRunner()
    ran = runner.invoke(app, ["run", str(spec), "--no-report"])
    assert ran.exit_code == 0, ran.output
    listed = _findings(spec)
    assert listed and all(row[1] == UNTESTED and "sweep3d grade" in row[2] for row in listed)
    assert "[untested]" in ran.output and "untested: sweep3d grade" in " ".join(ran.output.split())

    loaded = load_spec(spec)
    first = grade_findings(loaded, budget=96)
    assert len(first.grades) == len(listed) and first.rendered > 0
    graded = _findings(spec)
    assert [r[0] for r in graded] == [r[0] for r in listed]  # every finding, in the printed order
    assert all(r[1] in GRADES for r in graded)
    boundary = next(r for r in graded if r[0].startswith("boundary brightness_contrast_brightness"))
    assert boundary[1] == SOLID, boundary  # fails exactly below a brightness: every check agrees
    assert boundary[3] and "mitsuba reproduces it" in boundary[2]

    again = grade_findings(loaded, budget=96)
    assert again.rendered == 0 and again.grades == first.grades

    marked = runner.invoke(app, ["run", str(spec), "--no-report"])
    assert "[solid]" in marked.output
    printed = runner.invoke(app, ["grade", str(spec), "--budget", "96"])
    assert printed.exit_code == 0, printed.output
    assert "solid: " in printed.output and "renders of the budget's 96 used (0 rendered now)" in \
        " ".join(printed.output.split())
    # each check's progress lines follow a line naming it (its experiment and engine)
    assert re.search(r"-confirm-mitsuba: \d+ fresh configurations on mitsuba", printed.output), printed.output
    assert re.search(r"-grade-mitsuba: \d+ fresh configurations on mitsuba", printed.output), printed.output


def test_grade_before_any_run_is_one_line(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, SPEC)
    result = CliRunner().invoke(app, ["grade", str(spec)])
    assert result.exit_code == 2
    assert "sweep3d run" in result.output and "Traceback" not in result.output
