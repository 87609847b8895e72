"""Issue 33 end to end, on the synthetic run (tests/helpers/realism.py): ``sweep3d realism pick``
writes a kit with the real edge images and ``align.html`` (no stand-ins); the page, opened in
headless Chromium with a fake camera, draws the render over the camera's frames and saves a
capture under its job's name; ``sweep3d realism score`` with that capture (and stand-in
photographs of the other jobs, :func:`photo_like`) stores the verdicts the model gives on them;
the report's Realism panel shows them.

The fake camera plays the target job's render with its red and blue swapped, so the test model
(red against blue) must disagree with the simulation on the captured photograph: the verdict
is checked against the model's answer on the saved capture worked out here with numpy.
"""

from __future__ import annotations

import base64
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
from sweep3d.report import write_report
from sweep3d.results.agreement import VERDICTS
from tests.helpers import ARTIFACTS, assert_clean, load_spec, open_page
from tests.helpers.realism import (
    LABELS,
    agreement_rows,
    fake_camera,
    hand,
    job_colours,
    make_run,
    open_align,
    redblue_row,
    write_y4m,
)

CAMERA_SIZE = (320, 240)  # width × height, 4:3 as a phone's
TOLERANCE = 14  # per channel: the fake camera's YUV 4:2:0 round trip, JPEG, scaling
PER_OBJECT = 4


def close(pixel, expected) -> bool:
    return bool(np.all(np.abs(np.asarray(pixel, float)[:3] - np.asarray(expected, float)) <= TOLERANCE))


@pytest.mark.browser
@pytest.mark.torch
def test_pick_photograph_with_the_page_score_and_read_the_panel(tmp_path: Path, chromium) -> None:
    spec = make_run(tmp_path)
    kit = tmp_path / "kit"
    result = CliRunner().invoke(app, ["realism", "pick", str(spec), "-o", str(kit), "--per-object", str(PER_OBJECT)])
    assert result.exit_code == 0, result.output
    jobs = json.loads((kit / "kit.json").read_text())["jobs"]
    assert len(jobs) == 2 * PER_OBJECT
    colours = job_colours()
    renders = {}
    for job in jobs:  # the real tools wrote an RGBA edge image of each render's size beside it
        with Image.open(kit / "renders" / f"{job}.png") as im:
            renders[job] = np.asarray(im.convert("RGB"))
        with Image.open(kit / "edges" / f"{job}.png") as im:
            assert im.mode == "RGBA" and im.size == renders[job].shape[1::-1]

    # the job to photograph with the page: the clearest verdict; the camera shows it red for blue
    target = max(jobs, key=lambda j: abs(colours[j]["rgb"][0] - colours[j]["rgb"][2]))
    r, g, b = colours[target]["rgb"]
    scene = (b, g, r)
    w, h = CAMERA_SIZE
    video = write_y4m(tmp_path / "camera.y4m", np.broadcast_to(np.array(scene, np.uint8), (h, w, 3)).copy())
    photos = tmp_path / "photos"
    photos.mkdir()
    page_path = kit / "align.html"
    with fake_camera(chromium, video) as browser, open_align(browser, page_path) as (page, events):
        assert page.evaluate("() => document.documentElement.dataset.mode") == "live"
        page.wait_for_function("() => { const v = document.getElementById('video');"
                               " return !v.paused && v.readyState >= 2 && v.currentTime > 0.2; }", timeout=15_000)
        for _ in range(jobs.index(target)):
            page.click("#next")
        assert page.evaluate("() => document.getElementById('job').textContent") == str(target)
        uri = "data:image/png;base64," + base64.b64encode((kit / "renders" / f"{target}.png").read_bytes()).decode()
        assert page.evaluate("() => document.getElementById('overlay').src") == uri

        # the overlay drawn over the camera's frames: the blend inside it, the camera beside it
        page.fill("#opacity", "70")
        left, top, width, height = page.evaluate(
            "() => { const b = document.getElementById('overlay').getBoundingClientRect();"
            " return [b.left, b.top, b.width, b.height]; }")
        assert width > 0 and height > 0 and left > 4
        pixels = np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB")).astype(int)
        camera = pixels[round(top + height / 2), max(2, round(left / 2))]
        assert close(camera, scene), camera
        drawn = pixels[round(top + height / 2), round(left + width / 2)]
        assert close(drawn, 0.7 * np.array(colours[target]["rgb"]) + 0.3 * camera), (drawn, camera)
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "realism-e2e-align.png"))

        # capture: saved under the job's name, the camera's frame without the overlay
        with page.expect_download() as download:
            page.click("#capture")
        assert download.value.suggested_filename == f"{target}.jpg"
        download.value.save_as(photos / f"{target}.jpg")
        assert_clean(page_path, events)
    with Image.open(photos / f"{target}.jpg") as captured:
        assert captured.format == "JPEG" and captured.size == CAMERA_SIZE
        assert np.abs(np.asarray(captured.convert("RGB")).astype(int) - scene).max() <= TOLERANCE

    for job in jobs:  # the other scenes "photographed" by the documented transformation
        if job != target:
            (photos / f"{job}.jpg").write_bytes(photo_like(renders[job], seed=job))
    result = CliRunner().invoke(app, ["realism", "score", str(spec), str(photos), "--kit", str(kit)])
    assert result.exit_code == 0, result.output

    # the stored verdicts are the model's on each photograph as score frames it (numpy, here)
    sim, seen = {}, {}
    for job in jobs:
        label = LABELS[colours[job]["object"]]
        sim[job] = redblue_row(renders[job], label)["correct"]
        seen[job] = redblue_row(framed(upright(photos / f"{job}.jpg"), *renders[job].shape[:2]), label)["correct"]
    assert seen[target] != sim[target]  # the swapped scene: a disagreement, as it should be
    stored = {r["job"]: r for r in Store(tmp_path / "store").table(VERDICTS).to_pylist()}
    assert sorted(stored) == jobs and {r["source"] for r in stored.values()} == {"photo"}
    assert {job: r["correct"] for job, r in stored.items()} == seen
    assert stored[target]["photo"] == f"{target}.jpg"
    rows = {r["object"]: r for r in agreement_rows(tmp_path)}
    for obj in (*LABELS, None):
        want = hand([(sim[j], seen[j]) for j in jobs if obj is None or colours[j]["object"] == obj])
        for key in ("n", "n_agree", "agreement", "ppv", "npv", "kappa"):
            assert rows[obj][key] == (pytest.approx(want[key]) if want[key] is not None else None), (obj, key)

    # the report's Realism panel: the table and the pairs, the captured photograph among them
    report = write_report(load_spec(spec))
    with open_page(chromium, report) as (page, events):
        table = page.evaluate("Array.from(document.querySelectorAll('#realism table.realism tbody tr'))"
                              ".map(r => Array.from(r.cells).map(c => c.textContent.trim()))")
        assert [row[1] for row in table] == ["all objects", *sorted(LABELS)]
        overall = hand([(sim[j], seen[j]) for j in jobs])
        assert table[0][2] == str(len(jobs)) and table[0][3] == f"{overall['agreement']:.0%} ({overall['n_agree']})"
        pairs = page.evaluate("Array.from(document.querySelectorAll('#realism .realism-pair')).map(p => "
                              "[Number(p.dataset.job), p.classList.contains('disagree'), "
                              "Array.from(p.querySelectorAll('img')).map(i => i.naturalWidth)])")
        assert sorted(job for job, _, _ in pairs) == jobs
        for job, disagree, widths in pairs:
            assert disagree == (sim[job] != seen[job]) and len(widths) == 2 and all(widths), (job, widths)
        disagreeing = [disagree for _, disagree, _ in pairs]
        assert disagreeing[0] and disagreeing == sorted(disagreeing, reverse=True)  # disagreements first
        page.locator("#realism").screenshot(path=str(ARTIFACTS / "realism-e2e-panel.png"))
        assert_clean(report, events)
