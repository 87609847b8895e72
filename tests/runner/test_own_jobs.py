"""Results read through a spec are that spec's own jobs, whatever last ran under its experiment's
name (issue 35): another version of the spec, a notebook cell edited and not run, a spec file
edited after it was loaded. Runs are made here without Blender or a model: the plans a run would
record (:func:`sweep3d.runner.pipeline.plans_as_run`), written as a run writes them, and a synthetic
prediction and image for each job."""

from __future__ import annotations

import logging
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

import sweep3d
import sweep3d.results.own_jobs as own_jobs
from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.core.errors import UserError
from sweep3d.driver.plugin_code import SPEC_METADATA
from sweep3d.runner.pipeline import outcomes_by_scene, plan_spec, write_jobs
from tests.helpers import SPEC_02, SPEC_03, fake_run, predict, write_cube

#: Another version sharing no job with those (other yaws).
SPEC_OTHER = SPEC_02.replace("yaw = [0, 45]", "yaw = [10, 20]")


#: An adaptive version: each round's points depend on the outcomes of the earlier rounds.
ADAPTIVE = SPEC_02.replace("yaw = [0, 45]", "yaw = { range = [0, 90] }").replace(
    'type = "grid"', 'type = "adaptive"\nsamples = 6\ninitial = 2\nbatch = 2')








def load(folder: Path, text: str) -> sweep3d.Experiment:
    """The spec as a notebook loads it: TOML text (no file), relative to ``folder``."""
    return sweep3d.load(text, base=folder)


def blurs(experiment: sweep3d.Experiment) -> list[float]:
    return sorted(experiment.dataframe()["blur_sigma"].unique().tolist())


def warnings_of(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "sweep3d.results"]


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    write_cube(tmp_path)
    return tmp_path


def test_another_version_last_run_gives_the_loaded_specs_own_results(folder: Path, caplog) -> None:
    """The issue's case: a notebook's spec (blur 0 and 2) read after a run of the experiment with
    blur 0 and 3 gave blur 3's results, and exported nothing for blur 2. Its results are in the
    store (it ran before), so they are read, all of them and only them, without a warning."""
    caplog.set_level(logging.WARNING, "sweep3d.results")
    mine = load(folder, SPEC_02)
    fake_run(mine)
    fake_run(load(folder, SPEC_03))  # the experiment's last run: the other version

    assert blurs(mine) == [0.0, 2.0]
    own = sorted(j.pred_key for j in mine.plan().jobs)
    assert sorted(mine.dataframe()["pred_key"]) == own
    assert mine.sql("SELECT blur_sigma, count(*) AS n FROM results GROUP BY ALL ORDER BY 1").to_pylist() == [
        {"blur_sigma": 0.0, "n": 4}, {"blur_sigma": 2.0, "n": 4}]
    assert mine.sql("SELECT accuracy FROM control_accuracy WHERE parameter = 'blur_sigma' ORDER BY level"
                    ).column("accuracy").to_pylist() == [1.0, 0.0]
    exported = mine.export("imagefolder", folder / "out", where="blur_sigma = 2")
    assert exported.added == 4 and len(list((folder / "out" / "carton").iterdir())) == 4
    assert warnings_of(caplog) == []

    spec_file = folder / "spec.toml"  # the command line reads through the spec the same way
    spec_file.write_text(SPEC_02)
    result = CliRunner().invoke(app, ["query", str(spec_file), "SELECT DISTINCT blur_sigma FROM results ORDER BY 1",
                                      "--format", "csv"])
    assert result.exit_code == 0, result.output
    assert result.stdout.split() == ["blur_sigma", "0.0", "2.0"]


def test_the_report_of_another_version_is_its_own_with_its_own_run(folder: Path) -> None:
    fake_run(load(folder, SPEC_02), "run-of-blur-2")
    fake_run(load(folder, SPEC_03), "run-of-blur-3")
    page = load(folder, SPEC_02).report(folder / "page.html").read_text()
    assert "run-of-blur-2" in page and "run-of-blur-3" not in page
    page = load(folder, SPEC_03).report(folder / "page.html").read_text()
    assert "run-of-blur-3" in page


def test_the_spec_that_last_ran_is_read_as_it_is_without_planning(folder: Path, monkeypatch) -> None:
    """Query and report after a run pay nothing: the jobs file records the spec that planned it."""
    fake_run(load(folder, SPEC_02))
    fake_run(load(folder, SPEC_03))

    def planned(*args):
        raise AssertionError("planned again")

    monkeypatch.setattr(own_jobs, "write_own_jobs", planned)
    assert blurs(load(folder, SPEC_03)) == [0.0, 3.0]


def test_a_version_never_run_warns_how_many_of_its_jobs_have_no_result(folder: Path, caplog) -> None:
    caplog.set_level(logging.WARNING, "sweep3d.results")
    fake_run(load(folder, SPEC_03))
    mine = load(folder, SPEC_02)

    assert blurs(mine) == [0.0]  # blur 2 never ran: left out, never blur 3 in its place
    (warning,) = warnings_of(caplog)
    assert "experiment 'tiny' last ran another version of the spec" in warning
    assert "4 of its 8 jobs have none yet" in warning and "call .run()" in warning
    exported = mine.export("imagefolder", folder / "out", where="blur_sigma = 2")
    assert exported.added == 0 and len(warnings_of(caplog)) == 2


def test_a_version_with_no_result_at_all_is_an_error_saying_to_run_it(folder: Path) -> None:
    fake_run(load(folder, SPEC_03))
    spec_file = folder / "other.toml"
    spec_file.write_text(SPEC_OTHER)
    with pytest.raises(UserError, match=r"none of this one's 8 jobs has a result yet; run it: call \.run\(\)"):
        load(folder, SPEC_OTHER).dataframe()
    with pytest.raises(UserError, match=rf"run it: sweep3d run {spec_file} \(in Python"):
        sweep3d.load(spec_file).sql("SELECT count(*) FROM results")


def test_a_spec_file_edited_after_loading_is_still_read_as_loaded(folder: Path) -> None:
    """A notebook holds the spec it loaded: the file edited and run since is another version."""
    spec_file = folder / "spec.toml"
    spec_file.write_text(SPEC_02)
    loaded = sweep3d.load(spec_file)
    fake_run(loaded)
    spec_file.write_text(SPEC_03)
    fake_run(sweep3d.load(spec_file))

    assert blurs(loaded) == [0.0, 2.0]
    assert blurs(sweep3d.load(spec_file)) == [0.0, 3.0]


def test_a_jobs_file_that_records_no_spec_is_read_as_before(folder: Path) -> None:
    """A store last run before runs recorded their spec (or a jobs table written by hand) is read
    as it is: nothing tells whose jobs they are."""
    fake_run(load(folder, SPEC_03))
    store = Store(folder / "store")
    path = store.jobs_path("tiny")
    table = pq.read_table(path)
    metadata = {k: v for k, v in table.schema.metadata.items() if k != SPEC_METADATA}
    store.write_table_file(path, table.replace_schema_metadata(metadata))

    assert blurs(load(folder, SPEC_02)) == [0.0, 3.0]


def test_an_adaptive_versions_rounds_are_planned_again_from_the_stored_outcomes(folder: Path, caplog) -> None:
    """Its jobs are those its run recorded after its last round, not its first round's alone."""
    caplog.set_level(logging.WARNING, "sweep3d.results")
    mine = load(folder, ADAPTIVE)
    store = Store(mine.store)
    plan, previous, rounds = plan_spec(mine.spec), None, 0  # the run's passes: a round adding no job is the last
    while True:
        predict(plan, store)
        write_jobs(plan, store)
        rounds += 1
        if previous is not None and len(plan.jobs) <= len(previous.jobs):
            break
        previous, plan = plan, plan_spec(mine.spec, history=outcomes_by_scene(plan, store))
    fake_run(load(folder, SPEC_03))

    assert rounds > 2 and len(plan.jobs) > len(plan_spec(mine.spec).jobs)
    assert sorted(mine.dataframe()["pred_key"]) == sorted(j.pred_key for j in plan.jobs)
    assert warnings_of(caplog) == []
