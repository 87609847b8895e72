"""``sweep3d grade`` on the Ray executor: every check's renders (the stability check's neighbours,
the replication's twins, the second renderer's) made by Ray actors through the runner, under the
keys a local grading finds cached, with the same grades."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.followups.grade import grade_findings
from tests.helpers import load_spec
from tests.helpers.planted import bright_spec

pytestmark = [pytest.mark.slow, pytest.mark.blender, pytest.mark.torch]


def test_grade_on_ray_renders_what_a_local_grading_finds_cached(ray_cluster, tmp_path: Path) -> None:
    spec = bright_spec(tmp_path)
    assert CliRunner().invoke(app, ["run", str(spec), "--no-report"]).exit_code == 0
    on_ray = CliRunner().invoke(app, ["grade", str(spec), "--budget", "64", "--executor", "ray"])
    assert on_ray.exit_code == 0, on_ray.output
    assert "rendered now" in on_ray.output and "(0 rendered now)" not in on_ray.output
    here = grade_findings(load_spec(spec), budget=64)
    assert here.rendered == 0
    assert [g for g, _ in here.grades] and all(f"{g}: " in on_ray.output for g, _ in here.grades)
