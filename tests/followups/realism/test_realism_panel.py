"""The report's Realism panel: absent without another source's verdicts; with them, the agreement
table (per object and over all objects) and every render | photo pair with both verdicts, the
disagreements first, then the objects in turn, every image drawn (checked in headless Chromium);
past a page of pairs, the rest in pages a click away, each saying which pairs it holds; and
another renderer as the source says what it shares with Cycles."""

from __future__ import annotations

import hashlib
import io
from datetime import datetime, timezone
from pathlib import Path

import pytest
from PIL import Image

from sweep3d.cache.store import Store
from sweep3d.followups.realism.photos import photo_like
from sweep3d.report import write_report
from sweep3d.results.agreement import VERDICT_SCHEMA, VERDICTS, photo_path
from tests.helpers import ARTIFACTS, assert_clean, load_spec, open_page
from tests.helpers.realism import image_of, job_colours, make_run, sim_verdicts, verdict

T2 = datetime(2024, 3, 1, tzinfo=timezone.utc)


def scored_run(folder: Path) -> tuple[Path, dict[int, bool]]:
    """A synthetic run with photo verdicts of every third job (every other one flipped) and the
    photographs kept as ``realism score`` keeps them. Returns the spec and the verdicts."""
    spec = make_run(folder)
    sim, colours = sim_verdicts(), job_colours()
    store = Store(folder / "store")
    photos, rows = {}, []
    for n, job in enumerate(range(0, len(sim), 3)):
        photos[job] = sim[job] if n % 2 else not sim[job]
        data = photo_like(image_of(colours[job]["rgb"]), seed=job)
        sha = hashlib.sha256(data).hexdigest()
        path = photo_path(store, sha)
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.open(io.BytesIO(data)).save(path, format="JPEG")
        rows.append({**verdict(job, photos[job], at=T2), "photo": f"{job}.jpg", "photo_sha256": sha,
                     "preprocess": "EXIF orientation applied; framed as the render"})
    store.append(VERDICTS, rows, VERDICT_SCHEMA)
    return spec, photos


def panel_order(jobs, sim: dict[int, bool], other: dict[int, bool]) -> list[int]:
    """The pairs' order: disagreements first; then each object's first job, its second, ..."""
    objects = {i: j["object"] for i, j in enumerate(job_colours())}
    rank = {}
    for job in sorted(jobs):
        group = (sim[job] == other[job], objects[job])
        rank[job] = sum(1 for j in rank if (sim[j] == other[j], objects[j]) == group)
    return sorted(jobs, key=lambda j: (sim[j] == other[j], rank[j], objects[j], j))


def test_no_verdicts_no_realism_panel(tmp_path: Path) -> None:
    html = write_report(load_spec(make_run(tmp_path))).read_text()
    assert 'id="realism"' not in html


@pytest.mark.browser
def test_the_realism_panel_draws_the_table_and_the_pairs(tmp_path: Path, chromium) -> None:
    spec, photos = scored_run(tmp_path)
    sim = sim_verdicts()
    path = write_report(load_spec(spec))
    with open_page(chromium, path) as (page, events):
        table = page.evaluate("Array.from(document.querySelectorAll('#realism table.realism tbody tr'))"
                              ".map(r => Array.from(r.cells).map(c => c.textContent.trim()))")
        assert [r[1] for r in table] == ["all objects", "apple", "plum"]
        overall = table[0]
        assert overall[2] == str(len(photos))
        agree = sum(photos[j] == sim[j] for j in photos)
        assert overall[3] == f"{agree / len(photos):.0%} ({agree})"
        pairs = page.evaluate("Array.from(document.querySelectorAll('#realism .realism-pair'))"
                              ".map(p => [Number(p.dataset.job), p.classList.contains('disagree'), "
                              "p.querySelectorAll('figure.tile').length])")
        assert [job for job, _, _ in pairs] == panel_order(photos, dict(enumerate(sim)), photos)
        assert all(disagree == (photos[job] != sim[job]) and tiles == 2 for job, disagree, tiles in pairs)
        images = page.evaluate("Array.from(document.querySelectorAll('#realism .realism-pair img'))"
                               ".map(i => i.naturalWidth)")
        assert len(images) == 2 * len(photos) and all(width > 0 for width in images)
        ARTIFACTS.mkdir(exist_ok=True)
        page.locator("#realism").screenshot(path=str(ARTIFACTS / "realism-panel.png"))
        assert_clean(path, events)


def test_each_image_of_a_pair_names_its_job_and_configuration_on_hover(tmp_path: Path) -> None:
    """The hover text of both images of a pair: the job, its object, environment and control
    values (as the gallery's tiles say them), then what each source's verdict was."""
    import html
    import re

    spec, photos = scored_run(tmp_path)
    page = write_report(load_spec(spec)).read_text()
    section = re.search(r'<section id="realism"[^>]*>(.*?)</section>', page, re.S).group(1)
    colours = job_colours()
    for job in photos:
        pair = re.search(rf'<div class="realism-pair[^"]*" data-job="{job}"(.*?)</div>', section, re.S).group(1)
        render, photo = [html.unescape(t) for t in re.findall(r'<figure [^>]*title="([^"]*)"', pair)]
        scene = f"job {job} · object = {colours[job]['object']} · environment = "
        assert render.startswith(scene) and " · orientation_yaw = " in render and " · render: " in render, render
        assert photo.startswith(scene) and f" · photo {job}.jpg: " in photo, photo
        assert render.split(" · render: ")[0] == photo.split(" · photo ")[0]  # the same configuration on both


def test_every_pair_is_on_a_page_and_another_renderer_says_what_it_shares(tmp_path: Path) -> None:
    """Verdicts of every job from a photo source and from another engine: each source's pairs are
    all there once each, the first page open and the rest behind one click that says which pairs
    it holds; only the engine source carries the sentence on what it shares with Cycles."""
    import html
    import re

    from sweep3d.report.panels.realism import PAIRS

    spec = make_run(tmp_path)
    sim = dict(enumerate(sim_verdicts()))
    assert len(sim) > PAIRS
    photo = {job: sim[job] != (job % 5 == 0) for job in sim}
    engine = {job: sim[job] != (job % 7 == 0) for job in sim}
    rows = [verdict(job, photo[job], at=T2) for job in sim]
    rows += [verdict(job, engine[job], source="engine:mitsuba", at=T2) for job in sim]
    Store(tmp_path / "store").append(VERDICTS, rows, VERDICT_SCHEMA)
    page = write_report(load_spec(spec)).read_text()
    section = re.search(r'<section id="realism"[^>]*>(.*?)</section>', page, re.S).group(1)
    for source, other in (("photo", photo), ("engine:mitsuba", engine)):
        blocks = re.findall(rf'<div class="tiles realism-pairs" data-source="{source}"[^>]*>(.*?)\n</div>', section,
                            re.S)
        pages = [[int(j) for j in re.findall(r'data-job="(\d+)"', block)] for block in blocks]
        assert [job for jobs in pages for job in jobs] == panel_order(sim, sim, other)  # every pair, once
        assert [len(jobs) for jobs in pages] == [PAIRS, len(sim) - PAIRS]
        summaries = re.findall(rf'<details class="realism-page" data-source="{re.escape(source)}"><summary>(.*?)'
                               '</summary>', section)
        disagree = sum(sim[j] != other[j] for j in pages[1])
        assert [html.unescape(t) for t in summaries] == [
            f"pairs {PAIRS + 1}–{len(sim)} of {len(sim)}" + (f" ({disagree} disagree)" if disagree else "")]
    more = [html.unescape(t) for t in re.findall(r'<p class="note realism-more">(.*?)</p>', section)]
    assert more == [f"pairs 1–{PAIRS} of {len(sim)} above; the other {len(sim) - PAIRS} below, 1 click away."] * 2
    shares = re.findall(r'<p class="note realism-shares" data-source="([^"]*)">(.*?)</p>', section, re.S)
    assert [source for source, _ in shares] == ["engine:mitsuba"]
    text = html.unescape(re.sub(r"<[^>]+>", "", shares[0][1]))
    for said in ("not independent", "OBJ and MTL", "key light", "denoiser", "change of path tracer",
                 "does not show that the scene is realistic"):
        assert said in text, text
