"""The realism kit calibrates: its own renders, scored as photographs, give the run's verdicts back
(agreement 100 %, PPV = NPV = 1) on a spec with blur and noise.

A photograph of the scene is taken before any 2D control; ``score`` applies the job's controls
to it exactly once, as the postprocess stage applied them to the render. So the kit holds the
raw renders (byte for byte the render stage's blobs), and the images after the controls, scored
as photographs, get those controls twice and disagree: that is what a kit of post-processed
images did. The run is real past its renders (:func:`make_post_run`: renders planted, then
``sweep3d run``'s own postprocess and infer stages), and its model judges sharpness, which blur
and noise move.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.results import connect
from sweep3d.runner import plan_spec
from tests.helpers import load_spec
from tests.helpers.realism import agreement_rows, make_post_run, pick, stub_kit_tools


def score(spec: Path, photos: Path):
    return CliRunner().invoke(app, ["realism", "score", str(spec), str(photos), "--kit", str(spec.parent / "kit")])


def photographs(folder: Path, blobs: dict[int, Path]) -> Path:
    folder.mkdir()
    for job, path in blobs.items():
        shutil.copyfile(path, folder / f"{job}.png")
    return folder


@pytest.mark.torch
def test_the_kit_s_own_renders_as_photographs_agree_everywhere_despite_blur_and_noise(tmp_path: Path,
                                                                                       monkeypatch) -> None:
    spec = make_post_run(tmp_path)
    stub_kit_tools(monkeypatch)
    result = pick(spec, tmp_path / "kit", "--per-object", "40")
    assert result.exit_code == 0, result.output
    jobs = json.loads((tmp_path / "kit" / "kit.json").read_text())["jobs"]
    planned = {job.index: job for job in plan_spec(load_spec(spec)).jobs}
    store = Store(tmp_path / "store")
    blurred = [j for j in jobs if planned[j].values["blur"]["sigma"] > 0]
    noisy = [j for j in jobs if planned[j].values["noise"]["std"] > 0]
    assert blurred and noisy and set(jobs) - set(blurred) - set(noisy)  # every kind of job was picked
    for job in jobs:  # the kit's render is the raw render, before the job's blur and noise
        kept = (tmp_path / "kit" / "renders" / f"{job}.png").read_bytes()
        assert kept == store.blob_path(planned[job].render_key).read_bytes(), job

    # the images after the 2D controls (what the kit held before) get them twice: verdicts move
    twice = score(spec, photographs(tmp_path / "after", {j: store.blob_path(planned[j].image_key) for j in jobs}))
    assert twice.exit_code == 0, twice.output
    overall = next(r for r in agreement_rows(tmp_path) if r["overall"])
    assert overall["agreement"] < 1
    moved = _moved(tmp_path)
    assert moved and moved <= set(blurred) | set(noisy)

    # the kit's own renders: once, as the render got them — every verdict comes back
    once = score(spec, photographs(tmp_path / "raw", {j: tmp_path / "kit" / "renders" / f"{j}.png" for j in jobs}))
    assert once.exit_code == 0, once.output
    rows = agreement_rows(tmp_path)
    assert {r["object"] for r in rows} == {"apple", "plum", None}
    for row in rows:
        assert row["n_sim_right"] > 0 and row["n_sim_wrong"] > 0, row  # PPV and NPV both measured
        assert (row["agreement"], row["ppv"], row["npv"], row["kappa"]) == (1.0, 1.0, 1.0, 1.0), row
    assert next(r for r in rows if r["overall"])["n"] == len(jobs)
    said = {r["preprocess"] for r in store.table("verdicts").to_pylist()}  # the model's numbers, in words
    assert len(said) == 1 and said.pop().endswith("mean = (0.0, 0.0, 0.0), std = (1.0, 1.0, 1.0)")



def _moved(folder: Path) -> set[int]:
    """The jobs whose photograph's verdict is not their render's (the ``source_verdicts`` view)."""
    con = connect(Store(folder / "store"), "realism")
    return {job for job, in con.execute("SELECT job FROM source_verdicts WHERE sim_correct <> source_correct").fetchall()}
