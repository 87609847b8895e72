"""``sweep3d stability`` end to end: on a tiny real run (32 px, so the model resizes and every
change applies), cached under its keys (its bad inputs are in tests/cli/test_bad_input.py). These
checks ask for one round (``--max-sample`` = ``--sample``) of image changes (``--no-scene``); the
rounds are tested in test_stability_stage.py and test_sequential.py, the scene neighbours in
test_scene_check.py."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app


def test_the_check_stores_a_row_per_image_and_change_and_recomputes_nothing(tiny_copy: Path) -> None:
    spec = str(tiny_copy / "spec.toml")
    first = CliRunner().invoke(app, ["stability", spec, "--sample", "2", "--max-sample", "2", "--seed", "3", "--no-scene"])
    assert first.exit_code == 0, first.output
    assert "stability check of 2 images (0 cached, 2 inferred now; seed 3)" in first.output
    assert "fragile:" in first.output and "flips per change:" in first.output
    rows = Store(tiny_copy / "store").table("stability")
    assert rows is not None and rows.num_rows == 6  # 2 images × noise, dither, resize (32 px: the model resizes)
    assert set(rows.column("change").to_pylist()) == {"noise", "dither", "resize"}
    margins = rows.column("base_margin").to_pylist()
    assert all(-1.0 <= m <= 1.0 for m in margins)
    flipped = rows.column("flipped").to_pylist()
    assert flipped == [a != b for a, b in zip(rows.column("base_correct").to_pylist(),
                                               rows.column("correct").to_pylist())]

    again = CliRunner().invoke(app, ["stability", spec, "--sample", "2", "--max-sample", "2", "--seed", "3", "--no-scene"])
    assert again.exit_code == 0 and "(2 cached, 0 inferred now; seed 3)" in again.output
    assert Store(tiny_copy / "store").table("stability").num_rows == 6
    images = 4  # of the run's 8 (a sample beyond the results is all of them: tests/results/test_fragile.py)
    every = CliRunner().invoke(app, ["stability", spec, "--sample", str(images), "--max-sample", str(images), "--seed", "3", "--no-scene"])
    assert every.exit_code == 0, every.output  # the sample grows: only the new images are inferred
    assert Store(tiny_copy / "store").table("stability").num_rows == 3 * images
    assert f"stability check of {images} images (2 cached, {images - 2} inferred now; seed 3)" in every.output
    seed_3 = set(Store(tiny_copy / "store").table("stability").column("pred_key").to_pylist())
    other = CliRunner().invoke(app, ["stability", spec, "--sample", str(images), "--max-sample", str(images), "--seed", "4", "--no-scene"])
    assert other.exit_code == 0  # new noise and dither, the resize rows reused
    rows = Store(tiny_copy / "store").table("stability")
    seed_4 = {key for key, change, seed in zip(rows.column("pred_key").to_pylist(), rows.column("change").to_pylist(),
                                               rows.column("seed").to_pylist()) if change == "noise" and seed == 4}
    assert len(seed_4) == images  # seed 4 orders the sample its own way: an image new to the check gets a resize row
    assert rows.num_rows == 3 * images + 2 * images + len(seed_4 - seed_3)
    images = len(seed_3 | seed_4)  # what the run and the report count: every image checked

    run = CliRunner().invoke(app, ["run", spec, "--no-report"])
    assert run.exit_code == 0, run.output
    assert "fragile: " in run.output and f"stability check of {images} images" in run.output
    report = CliRunner().invoke(app, ["report", spec])
    assert report.exit_code == 0, report.output
    page = next((tiny_copy / "store" / "reports").glob("*.html")).read_text()
    assert f"stability check of {images} images" in page and "Fragile: " in page  # the failures panel says it




def test_the_check_appends_as_it_goes_and_a_stopped_one_resumes(tiny_copy: Path, monkeypatch) -> None:
    """Its rows were appended only at its end: a kill lost every inference (the rerun started from
    0 cached). They are appended as the check goes (every few seconds; here at once), so what was
    inferred before a stop is kept and the next check infers only the rest (issue 45, item 9)."""
    from sweep3d.cache.store import SegmentWriter
    from sweep3d.followups.stability import check

    spec = str(tiny_copy / "spec.toml")
    store = Store(tiny_copy / "store")
    monkeypatch.setattr(Store, "segment_writer", lambda self, table, schema=None, every=3.0, max_rows=64:
                        SegmentWriter(self, table, schema, 0.0, max_rows))  # due at every row: a kill keeps them
    rows_of_batch = check._rows
    batches: list[int] = []

    def stopped_in_the_second(*args, **kwargs):
        batches.append(len(batches))
        if len(batches) == 2:  # the first batch (2 images × 3 changes) is in the store already
            assert store.table("stability").num_rows == 6
            raise KeyboardInterrupt
        return rows_of_batch(*args, **kwargs)

    monkeypatch.setattr(check, "_rows", stopped_in_the_second)
    first = CliRunner().invoke(app, ["stability", spec, "--sample", "4", "--max-sample", "4", "--seed", "3", "--no-scene"])
    assert first.exit_code == 130 and "interrupted" in first.output, first.output
    assert store.table("stability").num_rows == 6
    monkeypatch.setattr(check, "_rows", rows_of_batch)
    again = CliRunner().invoke(app, ["stability", spec, "--sample", "4", "--max-sample", "4", "--seed", "3", "--no-scene"])
    assert again.exit_code == 0 and "stability check of 4 images (2 cached, 2 inferred now; seed 3)" in again.output
    assert store.table("stability").num_rows == 12
