"""``sweep3d realism score``: photographs matched to their jobs, read upright, framed as their
render and classified by the run's own model code; the verdicts stored as source ``photo``.

The renders themselves as photographs (stored rotated, with an EXIF orientation that turns them
upright) agree with the simulation on every job: agreement 100 %, PPV = NPV = 1. Photographs
made by the documented transformation (:func:`sweep3d.followups.realism.photos.photo_like`: white
balance, 3° rotation, sensor noise, JPEG 70) give the agreement a hand computation gives from
the test model's answers on them. Every bad input is one line, exit 2, and stores nothing.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.followups.realism.photos import framed, photo_like, upright
from sweep3d.results.agreement import VERDICTS
from tests.helpers.realism import (
    LABELS,
    agreement_rows,
    hand,
    image_of,
    job_colours,
    make_run,
    redblue_row,
    stub_kit_tools,
)

PER_OBJECT = 6


def kit(tmp_path: Path, monkeypatch) -> tuple[Path, list[int]]:
    spec = make_run(tmp_path)
    stub_kit_tools(monkeypatch)
    result = CliRunner().invoke(app, ["realism", "pick", str(spec), "-o", str(tmp_path / "kit"),
                                      "--per-object", str(PER_OBJECT)])
    assert result.exit_code == 0, result.output
    return spec, json.loads((tmp_path / "kit" / "kit.json").read_text())["jobs"]


def score(spec: Path, photos: Path, *extra: str):
    return CliRunner().invoke(app, ["realism", "score", str(spec), str(photos), "--kit",
                                    str(spec.parent / "kit"), *extra])


def sideways_png(pixels: np.ndarray) -> bytes:
    """``pixels`` stored turned a quarter, with the EXIF orientation (6) that shows them upright."""
    exif = Image.Exif()
    exif[0x0112] = 6
    out = io.BytesIO()
    Image.fromarray(pixels).transpose(Image.Transpose.ROTATE_90).save(out, format="PNG", exif=exif)
    return out.getvalue()


@pytest.mark.torch
def test_the_renders_as_photographs_agree_everywhere(tmp_path: Path, monkeypatch) -> None:
    spec, jobs = kit(tmp_path, monkeypatch)
    photos = tmp_path / "photos"
    photos.mkdir()
    for job in jobs:
        with Image.open(tmp_path / "kit" / "renders" / f"{job}.png") as im:
            (photos / f"{job}.png").write_bytes(sideways_png(np.asarray(im.convert("RGB"))))
        assert np.array_equal(upright(photos / f"{job}.png"),
                              np.asarray(Image.open(tmp_path / "kit" / "renders" / f"{job}.png").convert("RGB")))
    result = score(spec, photos)
    assert result.exit_code == 0, result.output
    assert "centre-cropped to their render's size" in result.output and "model's own preprocessing" in result.output
    rows = agreement_rows(tmp_path)
    assert {r["object"] for r in rows} == {*LABELS, None}
    for row in rows:
        assert row["agreement"] == 1.0 and row["ppv"] == 1.0 and row["npv"] == 1.0 and row["kappa"] == 1.0
        assert row["n"] == (len(jobs) if row["overall"] else PER_OBJECT)
    assert f"agrees with the render's on {len(jobs)} of {len(jobs)} jobs" in result.output


@pytest.mark.torch
def test_transformed_photographs_give_the_hand_computed_agreement(tmp_path: Path, monkeypatch) -> None:
    spec, jobs = kit(tmp_path, monkeypatch)
    photos = tmp_path / "photos"
    photos.mkdir()
    colours = job_colours()
    pairs = {}
    for job in jobs:
        with Image.open(tmp_path / "kit" / "renders" / f"{job}.png") as im:
            render = np.asarray(im.convert("RGB"))
        big = np.asarray(Image.fromarray(render).resize((48, 64)))  # a photo of another size and aspect
        (photos / f"{job}.jpg").write_bytes(photo_like(big, seed=job))
        label = LABELS[colours[job]["object"]]
        seen = framed(upright(photos / f"{job}.jpg"), *render.shape[:2])
        pairs[job] = (redblue_row(render, label)["correct"], redblue_row(seen, label)["correct"])
    assert len({a == b for a, b in pairs.values()}) == 2  # the transformation flips some verdicts, not all
    result = score(spec, photos)
    assert result.exit_code == 0, result.output
    got = {r["object"]: r for r in agreement_rows(tmp_path)}
    for obj in (*LABELS, None):
        want = hand([p for j, p in sorted(pairs.items()) if obj is None or colours[j]["object"] == obj])
        for key in ("n", "n_agree", "agreement", "ppv", "npv", "kappa"):
            assert got[obj][key] == (pytest.approx(want[key]) if want[key] is not None else None), (obj, key)


def test_each_bad_input_is_one_line_and_stores_nothing(tmp_path: Path, monkeypatch) -> None:
    spec, jobs = kit(tmp_path, monkeypatch)

    def folder(name: str, skip: int | None = None) -> Path:
        path = tmp_path / name
        path.mkdir()
        for job in jobs:
            if job != skip:
                (path / f"{job}.jpg").write_bytes(photo_like(image_of((200, 10, 10)), seed=job))
        return path

    stray = folder("stray")
    (stray / "9999.jpg").write_bytes((stray / f"{jobs[0]}.jpg").read_bytes())
    odd = folder("odd")
    (odd / "holiday.jpg").write_bytes((odd / f"{jobs[0]}.jpg").read_bytes())
    missing = folder("missing", skip=jobs[1])
    text = folder("text")
    (text / f"{jobs[2]}.jpg").write_text("not a picture")
    cut = folder("cut")
    (cut / f"{jobs[3]}.jpg").write_bytes((cut / f"{jobs[3]}.jpg").read_bytes()[:200])
    notes = folder("notes")
    (notes / "notes.txt").write_text("lens 28 mm")
    listing = folder("listing")
    (listing / "match.csv").write_text("photo,job\n" + "".join(f"{j}.jpg,{j}\n" for j in jobs[1:]) + "x.jpg,12345\n")
    cases = [(stray, (), ["9999.jpg: matches no job"]),
             (odd, (), ["holiday.jpg: matches no job"]),
             (missing, (), [f"job {jobs[1]}: has no photograph"]),
             (text, (), [f"{jobs[2]}.jpg: is not an image"]),
             (cut, (), [f"{jobs[3]}.jpg: cannot be decoded"]),
             (notes, (), ["notes.txt: is not a photograph"]),
             (listing, ("--match", str(listing / "match.csv")), ["x.jpg: matches no job", f"job {jobs[0]}: has no"])]
    for photos, extra, lines in cases:
        result = score(spec, photos, *extra)
        assert result.exit_code == 2, (photos.name, result.output)
        printed = result.output.strip().splitlines()
        assert len(printed) == len(lines), (photos.name, result.output)  # one each, and no note before them
        assert all(p.startswith("error: ") for p in printed), (photos.name, result.output)
        for line in lines:
            assert sum(line in p for p in printed) == 1, (photos.name, line, result.output)
        if photos is text:  # every format the store reads is named, not only two
            assert "(JPEG, PNG, WebP, TIFF or BMP)" in result.output
    assert not Store(tmp_path / "store").segments(VERDICTS)
    assert not (tmp_path / "store" / "realism").exists()


def test_a_real_run_s_renders_as_photographs_agree_with_it(tiny_copy: Path, monkeypatch) -> None:
    """End to end on the tiny real run (Blender renders, the built-in model, ONNX Runtime standing
    in for torch in the run): its own images, scored through torch, give its verdicts back."""
    stub_kit_tools(monkeypatch)
    spec = tiny_copy / "spec.toml"
    result = CliRunner().invoke(app, ["realism", "pick", str(spec), "--per-object", "4", "--near-ties", "mark"])
    assert result.exit_code == 0, result.output
    kit_dir = tiny_copy / "store" / "kits" / "tiny"  # the default: in the store
    jobs = json.loads((kit_dir / "kit.json").read_text())["jobs"]
    assert jobs and len(jobs) <= 4
    result = CliRunner().invoke(app, ["realism", "score", str(spec), str(kit_dir / "renders")])
    assert result.exit_code == 0, result.output  # the kit found by default in the store
    overall = next(r for r in agreement_rows(tiny_copy, "tiny") if r["overall"])
    assert (overall["n"], overall["agreement"]) == (len(jobs), 1.0)


def test_a_photo_gets_its_job_s_2d_controls_as_the_render_did(tmp_path) -> None:
    """A job blurred at σ = 1.5 is judged on a blurred photo (its blur is part of its configuration);
    a job at σ = 0 on the photo as taken; a control that reads the render's depth cannot apply."""
    import numpy as np

    from sweep3d.followups.realism.photos import PhotoProblems
    from sweep3d.followups.realism.score import post_processed
    from sweep3d.runner import plan_spec
    from tests.helpers import TINY_SPEC, load_spec, write_spec

    spec = load_spec(write_spec(tmp_path, TINY_SPEC))
    jobs = plan_spec(spec).jobs
    sharp = next(j.index for j in jobs if j.values["blur"]["sigma"] == 0.0)
    blurred = next(j.index for j in jobs if j.values["blur"]["sigma"] == 1.5)
    checks = (np.indices((32, 32)).sum(0) % 2 * 255).astype(np.uint8)[..., None].repeat(3, -1)
    out = post_processed(spec, {sharp: checks, blurred: checks})
    assert np.array_equal(out[sharp], checks)
    assert out[blurred].dtype == np.uint8 and out[blurred].std() < checks.std() / 4  # the checks are smoothed
    (tmp_path / "fog").mkdir()
    foggy = load_spec(write_spec(tmp_path / "fog", TINY_SPEC.replace('type = "blur"\nsigma = [0.0, 1.5]',
                                                                      'type = "fog"\ndensity = [0.0, 0.5]')))
    job = next(j.index for j in plan_spec(foggy).jobs if j.values["fog"]["density"] == 0.5)
    with pytest.raises(PhotoProblems, match=f"job {job}: control 'fog' reads the render's passes"):
        post_processed(foggy, {job: checks})


def test_the_summary_without_an_agreement_view_is_one_line_not_a_failure(tmp_path: Path) -> None:
    """The closing summary reads the ``agreement`` view only where it was made: without verdicts
    of the experiment, or on results lacking ``counted`` (an older store), it says so in one line."""
    import duckdb

    from sweep3d.followups.realism.score import _no_agreement, _scored
    from tests.helpers import load_spec

    spec = load_spec(make_run(tmp_path))
    lines = _scored("photo", spec, Store(tmp_path / "store"), []).lines()
    assert lines[0].startswith("stored 0 verdicts of source 'photo'")
    assert len(lines) == 2 and lines[1].startswith("no agreement to show: the store holds no readable verdict")
    con = duckdb.connect()
    con.execute("CREATE VIEW results_all AS SELECT 1 AS job, 'apple' AS object, true AS correct")
    line = _no_agreement(con, spec)
    assert "lack the column(s) counted" in line and f"sweep3d run {spec.path}" in line


@pytest.mark.torch  # its model module (tests/helpers/realism.py) is a torch module
def test_beside_another_command_s_hold_score_is_refused_before_the_models_run(tmp_path: Path, monkeypatch) -> None:
    """It classified every photograph first and took the store's lock last: during another spec's
    run its work was thrown away. Now it holds the lock before a model runs (issue 45, item 9)."""
    import os
    import threading

    from sweep3d.followups.realism import score as scoring

    spec, jobs = kit(tmp_path, monkeypatch)
    photos = tmp_path / "photos"
    photos.mkdir()
    for job in jobs:
        (photos / f"{job}.jpg").write_bytes(photo_like(image_of((200, 10, 10)), seed=job))

    def classify(*args, **kwargs):
        raise AssertionError("a model ran without the store's lock")

    monkeypatch.setattr(scoring, "classify", classify)
    root = tmp_path / "store"
    ready, release = threading.Event(), threading.Event()

    def hold() -> None:
        with Store(root).lock():
            ready.set()
            release.wait(60)

    holder = threading.Thread(target=hold)
    holder.start()
    try:
        assert ready.wait(30)
        result = score(spec, photos)
    finally:
        release.set()
        holder.join()
    assert result.exit_code == 2, result.output
    assert result.output.strip().splitlines()[-1] == (
        f"error: store {root} is in use by sweep3d pid {os.getpid()}; wait for it to finish or pass --wait SECONDS")
    assert not Store(root).segments(VERDICTS) and not (root / "realism").exists()
