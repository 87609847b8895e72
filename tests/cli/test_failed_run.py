"""A run whose every job failed (issue 45, item 5): ``run`` says that they failed and why (each
stage's first error), writes no report, and never advises running the command just run; a later
``report`` says the last run failed rather than "no results yet; run: sweep3d run". No render:
the run's outcome is made by hand, as a run that failed everywhere leaves it."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from sweep3d.api import Experiment
from sweep3d.cache.store import Store, utc_now
from sweep3d.cli import app
from sweep3d.driver.outcome import StageOutcome
from sweep3d.runner.pipeline import RunResult, write_jobs
from tests.helpers import TINY_SPEC, load_spec, plan_for, write_spec

FIRST_ERROR = ("RuntimeError: [parser.cpp:1718] At dictionary node \"root\": failed to instantiate texture plugin of "
               "type \"bitmap\"")


def _failed_everywhere(spec: Path) -> RunResult:
    """What a run of ``spec`` returns and stores when every render failed: its jobs file and a runs
    row (as ``runner.pipeline`` writes them), no prediction."""
    plan = plan_for(load_spec(spec), "0" * 64)
    store = Store(plan.spec.store)
    n = len(plan.jobs)
    render = StageOutcome("render", total=n, failed=n, errors=[f"render {j.render_key[:12]}: {FIRST_ERROR}"
                                                              for j in plan.jobs])
    infer = StageOutcome("infer", total=n, skipped=n)
    with store.lock():
        write_jobs(plan, store)
        store.append("runs", [{"run_id": "0dfd3a16fc5b", "experiment": plan.spec.name, "spec_path": str(spec),
                               "spec": spec.read_text(), "jobs": n, "started_at": utc_now(), "created_at": utc_now(),
                               "seconds": 1.5, "render_total": n, "render_failed": n, "postprocess_failed": 0,
                               "infer_failed": 0, "infer_skipped": n}])
    return RunResult("0dfd3a16fc5b", plan, [plan], [render, infer], 1.5, store)


def test_run_says_every_job_failed_and_why_and_writes_no_report(tmp_path: Path, monkeypatch) -> None:
    spec = write_spec(tmp_path, TINY_SPEC)
    monkeypatch.setattr(Experiment, "run", lambda self, **_: _failed_everywhere(spec))

    result = CliRunner().invoke(app, ["run", str(spec)])

    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output and "no results" not in result.output
    text = " ".join(result.output.split())  # the console wraps the line at its width
    assert text.count("error:") == 1, result.output
    error = text[text.index("error:"):]
    assert error.startswith("error: all 8 jobs failed, so there are no findings and no report was written; "
                            "render: 8 failed (RuntimeError: [parser.cpp:1718]"), error
    assert "fix what it names" in error and "sweep3d run" not in error
    reports = tmp_path / "store" / "reports"
    assert not reports.exists() or not list(reports.rglob("*.html"))


def test_report_after_a_run_that_failed_everywhere_says_so(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, TINY_SPEC)
    _failed_everywhere(spec)

    result = CliRunner().invoke(app, ["report", str(spec)])

    assert result.exit_code == 2, result.output
    [line] = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert "every job of its last run (run 0dfd3a16fc5b, 8 jobs) failed: render 8" in line, line
    assert "run: sweep3d run" not in line and "yet" not in line, line


def test_report_of_an_experiment_never_run_still_says_to_run_it(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, TINY_SPEC)
    (tmp_path / "store").mkdir()

    result = CliRunner().invoke(app, ["report", str(spec)])

    assert result.exit_code == 2, result.output
    assert f"run: sweep3d run {spec}" in result.output
