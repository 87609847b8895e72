"""``sweep3d stability`` end to end: on a tiny real run (32 px, so the model resizes and every
change applies), cached under its keys (its bad inputs are in tests/cli/test_bad_input.py)."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app


def test_the_check_stores_a_row_per_image_and_change_and_recomputes_nothing(tiny_copy: Path) -> None:
    spec = str(tiny_copy / "spec.toml")
    first = CliRunner().invoke(app, ["stability", spec, "--sample", "4", "--seed", "3"])
    assert first.exit_code == 0, first.output
    assert "stability check of 4 images (0 cached, 4 inferred now; seed 3)" in first.output
    assert "fragile:" in first.output and "flips per change:" in first.output
    rows = Store(tiny_copy / "store").table("stability")
    assert rows is not None and rows.num_rows == 12  # 4 images × noise, dither, resize (32 px: the model resizes)
    assert set(rows.column("change").to_pylist()) == {"noise", "dither", "resize"}
    margins = rows.column("base_margin").to_pylist()
    assert all(-1.0 <= m <= 1.0 for m in margins)
    flipped = rows.column("flipped").to_pylist()
    assert flipped == [a != b for a, b in zip(rows.column("base_correct").to_pylist(),
                                               rows.column("correct").to_pylist())]

    again = CliRunner().invoke(app, ["stability", spec, "--sample", "4", "--seed", "3"])
    assert again.exit_code == 0 and "(4 cached, 0 inferred now; seed 3)" in again.output
    assert Store(tiny_copy / "store").table("stability").num_rows == 12
    every = CliRunner().invoke(app, ["stability", spec, "--sample", "100", "--seed", "3"])
    assert every.exit_code == 0, every.output  # the sample grows: only the new images are inferred
    images = Store(tiny_copy / "store").table("stability").num_rows // 3
    assert images > 4 and f"({4} cached, {images - 4} inferred now; seed 3)" in every.output
    other = CliRunner().invoke(app, ["stability", spec, "--sample", "100", "--seed", "4"])
    assert other.exit_code == 0  # new noise and dither, the resize rows reused
    assert Store(tiny_copy / "store").table("stability").num_rows == 3 * images + 2 * images

    run = CliRunner().invoke(app, ["run", spec, "--no-report"])
    assert run.exit_code == 0, run.output
    assert "fragile: " in run.output and f"stability check of {images} images" in run.output
    report = CliRunner().invoke(app, ["report", spec])
    assert report.exit_code == 0, report.output
    page = next((tiny_copy / "store" / "reports").glob("*.html")).read_text()
    assert f"stability check of {images} images" in page and "Fragile: " in page  # the failures panel says it


