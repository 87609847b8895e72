"""A command's mistakes: options out of range or given together, a query that fails or writes
where it may not, a command on an experiment with no results yet or a store that does not exist.
Each is one ``error:`` line that says what to give instead, exit code 2, nothing written.

Mistakes in the spec are in tests/spec/test_bad_input.py; a user's plug-in code that raises or
exits is in tests/driver/test_bad_input.py."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from tests.helpers import TINY_SPEC, add_render, one_line, write_spec

runner = CliRunner()


@pytest.mark.parametrize(
    "args, text",
    [
        (["select nope from results"], "query failed"),
        (["select 1", "--output", "x.xlsx"], "unsupported format"),
    ],
)
def test_query_mistakes_are_one_line_errors(tiny_run, tmp_path, args, text):
    if "--output" in args:
        args = [*args[:-1], str(tmp_path / args[-1])]
    result = CliRunner().invoke(app, ["query", str(tiny_run / "spec.toml"), *args])
    assert result.exit_code == 2
    assert "Traceback" not in result.output
    assert text in result.output
    assert len([line for line in result.output.splitlines() if line.strip()]) == 1


def first_seconds_of_a_run(folder: Path) -> Path:
    """A spec whose store holds what a first run writes in its first seconds: renders, no results."""
    from tests.helpers import TINY_SPEC, write_spec

    spec = write_spec(folder, TINY_SPEC)
    add_render(Store(folder / "store"), "ab" * 20)
    return spec


@pytest.mark.parametrize("command", [["report"], ["query", "SELECT count(*) FROM results"],
                                     ["query", "SELECT * FROM failure_modes()"]])
@pytest.mark.parametrize("started", [False, True], ids=["never-run", "first-seconds"])
def test_query_and_report_before_any_result_say_so_in_one_line(tmp_path: Path, command: list[str],
                                                               started: bool) -> None:
    from tests.helpers import TINY_SPEC, write_spec

    spec = first_seconds_of_a_run(tmp_path) if started else write_spec(tmp_path, TINY_SPEC)
    result = CliRunner().invoke(app, [command[0], str(spec), *command[1:]])
    assert result.exit_code == 2, result.output
    line = one_line(result.output)
    assert f"no results for experiment 'tiny' yet in {tmp_path / 'store'}" in line
    assert f"run: sweep3d run {spec}" in line and "does not exist" not in line


READERS = [["query", "SELECT 1"], ["query", "SELECT 1", "--output", "rows.csv"], ["report"], ["compare"],
           ["export", "--format", "parquet"], ["stability"], ["confirm"], ["explain", "--no-report"],
           ["cache", "verify"], ["cache", "stats"], ["cache", "gc"], ["cache", "compact"], ["realism", "pick"],
           ["realism", "score", "--engine", "cycles"]]


@pytest.mark.parametrize("command", READERS, ids=[" ".join(c[:2]) if c[0] in ("cache", "realism") else c[0]
                                                  + ("-o" if "--output" in c else "") for c in READERS])
def test_a_reader_of_a_store_that_does_not_exist_says_so_and_writes_nothing(tmp_path: Path,
                                                                             command: list[str]) -> None:
    """No store yet: one line naming the store and ``sweep3d run SPEC``, exit 2, and the folder
    left as it was (no store, lock, summary cache, report or kit made)."""
    from tests.helpers import TWO_MODELS

    text = TINY_SPEC.replace('[model]\nbatch_size = 8\n', "") + TWO_MODELS if command[0] == "compare" else TINY_SPEC
    spec = write_spec(tmp_path, text)
    before = sorted(tmp_path.rglob("*"))
    args = [str(tmp_path / a) if a == "rows.csv" else a for a in command]
    at = 2 if args[0] in ("cache", "realism") else 1
    result = runner.invoke(app, [*args[:at], str(spec), *args[at:]])
    assert result.exit_code == 2, result.output
    line = one_line(result.output)
    assert f"no results for experiment 'tiny' yet in {tmp_path / 'store'}" in line, line
    assert f"sweep3d run {spec}" in line
    assert sorted(tmp_path.rglob("*")) == before


def test_a_check_before_any_result_or_of_another_task_is_one_line(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, TINY_SPEC)
    result = CliRunner().invoke(app, ["stability", str(spec)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "sweep3d run" in result.output
    boxed = tmp_path / "boxed"
    boxed.mkdir()
    spec = write_spec(boxed, TINY_SPEC + '\n[evaluator]\nkind = "localization"\n')
    result = CliRunner().invoke(app, ["stability", str(spec)])
    assert result.exit_code == 2 and 'kind = "classification"' in result.output


@pytest.mark.parametrize("table, key", [("angle = -1", "stability.angle"), ("light = 0.9", "stability.light"),
                                        ("distance = inf", "stability.distance"), ("scene = 2", "stability.scene"),
                                        ("yaw = 1", "stability.yaw")])
def test_a_bad_stability_step_is_one_line_naming_the_key(tmp_path: Path, table: str, key: str) -> None:
    """The scene neighbours' steps (``[stability]``): refused before anything is read or written."""
    spec = write_spec(tmp_path, TINY_SPEC + f"\n[stability]\n{table}\n")
    before = sorted(tmp_path.rglob("*"))
    result = runner.invoke(app, ["stability", str(spec)])
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    line = one_line(result.output)
    assert str(spec) in line and key in line, line
    assert sorted(tmp_path.rglob("*")) == before
    result = runner.invoke(app, ["stability", str(write_spec(tmp_path, TINY_SPEC, name="ok.toml")), "--executor",
                                 "cloud"])
    assert result.exit_code == 2 and "--executor cloud: use local or ray" in one_line(result.output)


@pytest.mark.parametrize("args, message", [
    (["--budget", "0"], "--budget 0: give the minutes the bench may take, a finite number > 0"),
    (["--budget", "-5"], "--budget -5: give the minutes"),
    (["--budget", "nan"], "--budget nan: give the minutes"),
    (["--budget", "10", "--jobs", "20"], "--budget 10 and --jobs 20 together: give one"),
])
def test_a_bad_budget_is_one_line_and_exit_code_2(tmp_path: Path, args: list[str], message: str) -> None:
    spec = write_spec(tmp_path, TINY_SPEC)
    result = runner.invoke(app, ["bench", str(spec), *args])
    assert result.exit_code == 2, result.output
    assert message in result.output and len(result.output.strip().splitlines()) == 1, result.output


def test_a_budget_too_short_for_one_job_is_one_line_and_exit_code_2(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, TINY_SPEC)
    result = runner.invoke(app, ["bench", str(spec), "--budget", "0.05"])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "--budget 0.05 min is too short" in lines[0], result.output
    assert not (tmp_path / "store" / "blobs").exists()  # refused before anything rendered
