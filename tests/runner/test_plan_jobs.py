"""``sweep3d plan --jobs N`` lists the first jobs: their scene, values and what is cached."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from sweep3d.cli import app
from tests.helpers import TINY_SPEC, write_spec


def test_plan_lists_the_first_jobs_with_their_values_and_cache_state(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, TINY_SPEC.replace('name = "box"', 'name = "[bold]box"'))
    result = CliRunner().invoke(app, ["plan", str(spec), "--jobs", "3"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    header = next(line for line in lines if "orientation_yaw" in line)
    assert all(name in header for name in ("job", "object", "environment", "blur_sigma", "rendered", "inferred"))
    rows = lines[lines.index(header) + 2: lines.index(header) + 5]  # under the header and its rule
    assert all(row.split("│")[2].strip() == "[bold]box" and row.count(" no ") == 2 for row in rows), rows
    assert [row.split("│")[4].strip() for row in rows] == ["0", "0", "45"]  # yaw: the grid's order
    assert "the first 3 of 8 jobs" in result.output
    assert "the first" not in CliRunner().invoke(app, ["plan", str(spec)]).output


def test_the_estimate_says_what_it_assumes_and_how_busy_the_machine_is() -> None:
    from sweep3d.cli.output import load_note

    assert load_note(2, 0.1) == "it assumes 2 free CPU cores, as they are now"
    busy = load_note(2, 2.0)  # another run on both cores: up to twice as long
    assert "busy now (load 2.0" in busy and busy.endswith("expect up to 2.0× as long")
    assert "up to 1.5×" in load_note(4, 2.0)
    assert "assumes" in load_note()  # this machine's own cores and load
