"""The HTML report: self-contained, drawn by a real browser, escaped, and a clear error when empty.

The browser tests drive the system's headless Chromium (``/usr/bin/chromium``, from apt) through
the ``playwright`` package; they skip, saying why, where that browser is missing. Screenshots of
each panel go to ``test-artifacts/`` (git-ignored). One browser serves the whole test run (the
``chromium`` fixture of ``tests/conftest.py``); ``open_page`` opens each page in a fresh context of
it, and is shared with the explorer and scale tests.
"""

from __future__ import annotations

import base64
import hashlib
import io
import json
import re
from pathlib import Path

import pytest
from PIL import Image
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.report import build_context, render_html, write_report
from sweep3d.report.page import SCRIPTS, plotly_js, script_json
from sweep3d.report.panel import Panel
from sweep3d.report.panels import PANELS, overall
from sweep3d.report.thumbs import SIZES, Thumbnails, thumbnail_size
from sweep3d.results import connect
from tests.helpers import (
    PANEL_IDS,
    TINY_SPEC,
    assert_clean,
    cell_centre,
    load_spec,
    open_page,
    page_thumbnails,
    screenshot_panels,
    write_spec,
)

SCRIPT = re.compile(r"<script\b[^>]*>.*?</script>", re.S | re.I)
INLINE_SCRIPT = re.compile(r"<script>(.*?)</script>", re.S)
DATA_URI = re.compile(r"data:image/(png|jpeg);base64,([A-Za-z0-9+/=]+)")
EXTERNAL = re.compile(r"""(?:src|href)\s*=\s*["']?\s*(?:https?:)?//|url\(\s*["']?\s*(?:https?:)?//|@import""", re.I)

EVIL_OBJECT = "box<script>alert(1)</script>"
EVIL_ENV = "</script><img src=x onerror=alert(2)> & <b>bold</b>"
EVIL_EXPERIMENT = "tiny</title><script>alert(3)</script>"


def results_count(folder: Path, where: str = "true") -> int:
    loaded = load_spec(folder / "spec.toml")
    con = connect(Store(loaded.store), loaded.name)
    return con.execute(f"SELECT count(*) FROM results WHERE {where}").fetchone()[0]




def test_report_is_self_contained(tiny_run: Path, tmp_path: Path) -> None:
    loaded = load_spec(tiny_run / "spec.toml")
    path = write_report(loaded)
    assert path == tiny_run / "store" / "reports" / "tiny.html"
    html = path.read_text(encoding="utf-8")

    markup = SCRIPT.sub("<script></script>", html)  # plotly.js names URLs in strings; markup must not
    assert not EXTERNAL.search(markup), EXTERNAL.search(markup)
    scripts = INLINE_SCRIPT.findall(html)
    assert len(scripts) == 1 + len(SCRIPTS)  # plotly.js, then the report's own; all data is JSON
    csp = re.search(r'http-equiv="Content-Security-Policy" content="([^"]+)"', html).group(1)
    assert "default-src &#39;none&#39;" in csp
    for script in scripts:  # each inline script is allowed by its hash, and only those
        digest = base64.b64encode(hashlib.sha256(script.encode()).digest()).decode()
        assert f"sha256-{digest}" in csp
    assert csp.count("sha256-") == len(scripts)
    assert html.count('type="application/json"') >= 2 + len(PANEL_IDS)  # thumbnails, explorer, figures
    assert len(html.encode()) < len(plotly_js().encode()) + 400_000

    thumbs = page_thumbnails(html)
    assert len(thumbs) == results_count(tiny_run, "true") == 8  # one per distinct image key
    assert len(set(thumbs)) == len(thumbs)
    for uri in thumbs:
        kind, data = DATA_URI.fullmatch(uri).groups()
        with Image.open(io.BytesIO(base64.b64decode(data))) as img:
            assert img.format == kind.upper() and max(img.size) <= SIZES[0][1]

    for text in ("tiny", "efficientnet-lite0", "orientation_yaw", "blur_sigma", "studio", "white", "box", "carton",
                 "control_accuracy", "failure_modes"):
        assert text in html
    for panel in PANEL_IDS:
        assert f'<section id="{panel}"' in html  # folded or not

    elsewhere = write_report(loaded, tmp_path / "out" / "r.html")
    assert elsewhere == tmp_path / "out" / "r.html" and elsewhere.stat().st_size > 0
    assert not [p for p in elsewhere.parent.iterdir() if p.name.endswith(".tmp")]


def test_script_json_cannot_close_the_script_element() -> None:
    text = json.dumps({"name": "</script><script>alert(1)</script> & <!--"})
    safe = str(script_json(text))
    assert not set("<>&") & set(safe)
    assert json.loads(safe) == json.loads(text)


def test_page_uses_the_plotly_bundle_matching_plotly_py() -> None:
    from plotly.offline import get_plotlyjs_version

    from sweep3d.report.page import PLOTLY_CARTESIAN

    header = plotly_js()[:200]
    assert f"v{get_plotlyjs_version()}" in header
    if PLOTLY_CARTESIAN.is_file():  # scripts/setup.sh installs it from the npm registry
        assert "cartesian" in header


def test_thumbnails_are_shared_by_key_downscaled_and_kept_within_the_budget(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    for key, shade in (("aa1", 40), ("bb2", 200), ("cc3", 120)):
        path = store.blob_path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.new("RGB", (224, 160), (shade, 90, 30)).save(path)
    thumbs = Thumbnails(store, expected=3)
    assert [thumbs.want(k) for k in ("aa1", "bb2", "aa1", "gone", "cc3")] == [0, 1, 0, 2, 3]
    uris = thumbs.data_uris()
    assert uris[2] is None and thumbs.missing == 1  # no blob: the page shows a placeholder
    with Image.open(io.BytesIO(base64.b64decode(DATA_URI.fullmatch(uris[0]).group(2)))) as img:
        assert img.size == (96, 69)
    small = Thumbnails(store, expected=3, budget=len(uris[0]) + 10)
    for key in ("aa1", "bb2", "cc3"):
        small.want(key)
    kept = small.data_uris()
    assert kept[0] == uris[0] and kept[1:] == [None, None] and small.left_out == 2  # first asked, first kept
    few = Thumbnails(store, expected=3, limit=2)
    assert [few.want(k) for k in ("aa1", "bb2")] == [0, 1] and few.remaining == 0
    few.want("cc3")  # beyond the count budget: left out, never read
    assert few.data_uris() == [uris[0], uris[1], None] and few.left_out == 1 and few.keys() == ["aa1", "bb2", "cc3"]
    assert thumbnail_size(100) == 96 and thumbnail_size(10_000) == 64


def test_a_damaged_image_is_never_embedded_and_the_page_says_why(tmp_path: Path) -> None:
    from sweep3d.cache.blobs import sha256_bytes

    store = Store(tmp_path / "store")
    rows = []
    for key, shade in (("aa1", 40), ("bb2", 200)):
        path = store.blob_path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.new("RGB", (32, 32), (shade, 90, 30)).save(path)
        rows.append({"image_key": key, "sha256": sha256_bytes(path.read_bytes())})
    store.append("images", rows)
    data = bytearray(store.blob_path("bb2").read_bytes())
    data[len(data) // 2] ^= 0xFF  # still a PNG that may decode: only its digest tells
    store.blob_path("bb2").write_bytes(bytes(data))
    thumbs = Thumbnails(store, expected=3)
    for key in ("aa1", "bb2", "gone"):
        thumbs.want(key)
    uris = thumbs.data_uris()
    assert uris[0] is not None and uris[1:] == [None, None]
    assert thumbs.problems == {1: "damaged", 2: "not in the store"}
    assert (thumbs.damaged, thumbs.missing, thumbs.left_out) == (1, 1, 0)


def test_optional_panels_show_only_with_data(tiny_run: Path) -> None:
    loaded = load_spec(tiny_run / "spec.toml")
    store = Store(loaded.store)
    absent = Panel("parts", "Part visibility", "panels/overall.html.j2", lambda inputs: None)
    present = Panel("extra", "Extra panel", "panels/overall.html.j2", overall.build)
    html = render_html(build_context(loaded, connect(store, loaded.name), store, PANELS + (absent, present)))
    assert 'id="parts"' not in html and "Part visibility" not in html
    assert '<section id="extra"' in html and '<a href="#extra">Extra panel</a>' in html








@pytest.mark.browser
def test_report_draws_in_chromium(tiny_run: Path, chromium) -> None:
    path = write_report(load_spec(tiny_run / "spec.toml"))
    failures = results_count(tiny_run, "valid AND NOT correct")
    with open_page(chromium, path) as (page, events):
        figures = page.evaluate("Array.from(document.querySelectorAll('script.fig-data')).map(s => s.dataset.target)")
        drawn = page.evaluate(
            "Array.from(document.querySelectorAll('.js-plotly-plot')).filter(d => d.querySelector('svg.main-svg'))"
            ".map(d => d.id)")
        assert set(figures) | {"explorer-plot"} == set(drawn)
        traces = set(page.evaluate(
            "Array.from(document.querySelectorAll('.js-plotly-plot')).flatMap(d => d.data.map(t => t.type))"))
        assert {"heatmap", "bar", "box", "scatter"} <= traces
        assert page.evaluate("document.querySelectorAll('#explorer-plot .hm image').length") == 1
        effects = page.evaluate("Array.from(document.querySelectorAll('#aggregate .plot')).map(d => d.id)")
        assert sum(e.startswith("fig-effect-") for e in effects) == 3  # environment, yaw, blur

        widths = page.evaluate("Array.from(document.querySelectorAll('.failure-tile img')).map(i => i.naturalWidth)")
        assert len(widths) == min(failures, 48) and all(w > 0 for w in widths)
        assert page.inner_text("#experiment") == "tiny"
        assert "box" in page.inner_text("#objects")

        # every figure exports as PNG, from the mode bar and from the API behind it
        titles = page.evaluate("Array.from(document.querySelectorAll('#fig-outcomes .modebar-btn'))"
                               ".map(b => b.dataset.title)")
        assert "Download plot as a PNG" in titles
        assert not [t for t in titles if "Share" in t or "Cloud" in t]  # nothing leaves the page
        png = page.evaluate("Plotly.toImage(document.getElementById('fig-outcomes'), {format: 'png'})")
        assert png.startswith("data:image/png;base64,")
        with page.expect_download() as download:
            page.hover("#explorer-plot")
            page.click("#explorer-plot .modebar-btn[data-title='Download plot as a PNG']")
        assert download.value.suggested_filename == "explorer-plot.png"

        screenshot_panels(page, "report")
        assert_clean(path, events)


@pytest.mark.browser
def test_names_are_escaped(tiny_copy: Path, chromium) -> None:
    spec = tiny_copy / "spec.toml"
    text = spec.read_text()
    for old, new in (("box", EVIL_OBJECT), ("white", EVIL_ENV), ("tiny", EVIL_EXPERIMENT)):
        text = text.replace(f'name = "{old}"', f"name = {json.dumps(new)}")
    spec.write_text(text)
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output

    path = write_report(load_spec(spec))
    assert path.parent == tiny_copy / "store" / "reports" and path.suffix == ".html"
    html = path.read_text(encoding="utf-8")
    for raw in ("<script>alert(", "<img src=x", "<b>bold"):
        assert raw not in html
    assert "box&lt;script&gt;alert(1)&lt;/script&gt;" in html

    with open_page(chromium, path) as (page, events):
        assert page.inner_text("#experiment") == EVIL_EXPERIMENT
        assert page.title().startswith(EVIL_EXPERIMENT)
        if results_count(tiny_copy, "valid AND NOT correct"):
            page.click("#failures .failure-table summary")  # each failure's scene, a click away
            gallery = page.inner_text("#failures")
            assert EVIL_OBJECT in gallery and EVIL_ENV in gallery
        assert EVIL_OBJECT in page.inner_text("#objects")
        for plot in ("explorer-plot", "fig-box-environment", "fig-box-object", "fig-effect-1"):
            ticks = page.evaluate(
                f"Array.from(document.querySelectorAll('#{plot} .xtick text, #{plot} .ytick text'))"
                ".map(t => t.textContent)")
            assert EVIL_OBJECT in ticks or EVIL_ENV in ticks, (plot, ticks)
        explorer = page.evaluate("Array.from(document.querySelectorAll('#explorer-plot .xtick text, "
                                 "#explorer-plot .ytick text')).map(t => t.textContent)")
        assert EVIL_OBJECT in explorer and EVIL_ENV in explorer

        page.mouse.click(*cell_centre(page, 0, 0))  # the gallery's captions and titles, built in JS
        page.wait_for_selector("#explorer-gallery .tile")
        titles = page.evaluate("Array.from(document.querySelectorAll('#explorer-gallery .tile')).map(t => t.title)")
        assert titles and all(EVIL_OBJECT in t for t in titles)
        assert EVIL_OBJECT in page.inner_text("#explorer-gallery h3")
        page.select_option("select[aria-label='role of environment']", "slider")
        assert EVIL_ENV in page.inner_text("#explorer-controls")

        assert not page.evaluate("Array.from(document.querySelectorAll('b')).some(b => b.textContent === 'bold')")
        assert page.evaluate("document.querySelectorAll('img[src]:not([src^=\"data:\"])').length") == 0
        assert page.evaluate("Array.from(document.scripts).filter(s => !s.type).length") == 1 + len(SCRIPTS)
        assert_clean(path, events)




def test_report_on_an_empty_store_says_how_to_fix(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, TINY_SPEC)
    result = CliRunner().invoke(app, ["report", str(spec)])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    assert "no results for experiment 'tiny' yet" in lines[0]
    assert f"sweep3d run {spec}" in lines[0]
    assert not (tmp_path / "store" / "reports").exists()


def test_a_report_on_a_full_disk_outside_the_store_says_to_write_it_elsewhere(tmp_path: Path, monkeypatch) -> None:
    """A real ENOSPC (the page's temp file is /dev/full): ``-o`` names a file outside the store,
    so moving the store would not help; the line says to write the page elsewhere."""
    import uuid

    from tests.helpers import FixedUuid, build_store, one_line

    spec = build_store(tmp_path / "run", 40, images=False)
    out = tmp_path / "pages" / "r.html"
    out.parent.mkdir()
    (out.parent / ".r.html.fixed.tmp").symlink_to("/dev/full")
    monkeypatch.setattr(uuid, "uuid4", FixedUuid)
    result = CliRunner().invoke(app, ["report", str(spec), "-o", str(out)])
    line = one_line(result.output)
    assert result.exit_code == 2, result.output
    assert line.startswith(f"error: cannot write {out}: the disk is full (No space left on device; "), line
    assert line.endswith("free some disk space, or write it to another disk with --output FILE.html"), line
    assert "experiment.store" not in line
    assert list(out.parent.iterdir()) == [] and Path("/dev/full").exists()


def test_after_a_cached_rerun_the_run_card_shows_the_run_that_computed_the_results(tmp_path: Path) -> None:
    """A rerun that found everything cached took 0.2 s: the card's headline stays the time of the
    run that computed the results, and says the rerun beside it."""
    from datetime import timedelta

    from sweep3d.cache.store import utc_now
    from tests.helpers import build_store

    spec = build_store(tmp_path / "run", 40, images=False)
    loaded = load_spec(spec)
    store = Store(loaded.store)

    def card() -> dict:
        return build_context(loaded, connect(store, loaded.name), store, ())["run"]

    first = card()
    assert (first["label"], first["id"], first["rerun"]) == ("latest run", "synthetic0", None)
    later = utc_now() + timedelta(minutes=5)
    store.append("runs", [{
        "run_id": "rerun", "experiment": loaded.name, "spec_path": str(spec), "spec": spec.read_text(),
        "jobs": 40, "started_at": later, "created_at": later, "seconds": 0.2,
        **{f"{stage}_{k}": v for stage in ("render", "postprocess", "infer")
           for k, v in (("total", 40), ("cached", 40), ("computed", 0), ("failed", 0))},
    }])
    shown = card()
    assert (shown["label"], shown["id"], shown["seconds"]) == ("run time", "synthetic0", "0.0 s")
    assert shown["rerun"] == f"rerun {later:%Y-%m-%d %H:%M} UTC in 0.2 s, everything cached"
    assert [(s["cached"], s["total"]) for s in shown["stages"]] == [(40, 40)] * 3  # the rerun's cache hits
