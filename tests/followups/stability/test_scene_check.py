"""``sweep3d stability``'s scene neighbours end to end, on the tiny real run (32 px, one sample):
rendered through the run's stages once, compared with their jobs' stored verdicts, and counted
by the views (the neighbours' steps and plan are tested without rendering in test_neighbours.py)."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.results import connect


def test_the_neighbours_render_once_and_their_verdicts_are_compared_with_their_jobs(tiny_copy: Path) -> None:
    spec = str(tiny_copy / "spec.toml")
    first = CliRunner().invoke(app, ["stability", spec, "--sample", "2", "--max-sample", "2", "--seed", "3"])
    assert first.exit_code == 0, first.output
    said = " ".join(first.output.split())
    store = Store(tiny_copy / "store")
    rows = store.table("stability").to_pylist()
    scene = [r for r in rows if r["neighbour_key"] is not None]
    assert len(scene) == 4 and {r["change"] for r in scene} == {"yaw+1°", "yaw-1°"}  # 2 images × yaw ±1°
    assert len(rows) - len(scene) == 6  # the image changes as before
    assert "scene neighbours (yaw ±1°): 4 of the sampled images' neighbours, 0 compared before, 4 now" in said
    assert "not moved: blur_sigma: applied to the image after rendering" in said
    assert "worst-of-neighbourhood accuracy" in said

    con = connect(store, "tiny")
    try:
        stored = dict(con.execute("SELECT pred_key, correct FROM results").fetchall())
        theirs = dict(con.execute("SELECT pred_key, correct FROM predictions").fetchall())
        for row in scene:  # each side as the run's infer stage stored it
            assert row["base_correct"] == stored[row["pred_key"]] and row["correct"] == theirs[row["neighbour_key"]]
            assert row["flipped"] == (row["base_correct"] != row["correct"])
        jobs = {r["pred_key"] for r in scene}
        correct = sum(stored[k] for k in jobs)
        worst = sum(stored[k] and all(r["correct"] for r in scene if r["pred_key"] == k) for k in jobs)
        assert con.execute("SELECT images, correct, worst_correct FROM neighbourhood_accuracy WHERE object IS NULL"
                           ).fetchone() == (len(jobs), correct, worst)
        flipped = {k for k in jobs if any(r["flipped"] for r in scene if r["pred_key"] == k)}
        assert {k for k, f in con.execute("SELECT pred_key, flipped_scene FROM stability_images").fetchall()
                if f} == flipped
    finally:
        con.close()

    again = CliRunner().invoke(app, ["stability", spec, "--sample", "2", "--max-sample", "2", "--seed", "3"])
    assert again.exit_code == 0, again.output
    assert "4 compared before, 0 now (0 renders made)" in " ".join(again.output.split())  # nothing rendered again
    assert store.table("stability").num_rows == len(rows)
