"""The HTML report: self-contained, drawn by a real browser, escaped, and a clear error when empty.

The browser tests drive the system's headless Chromium (``/usr/bin/chromium``, from apt) through
the ``playwright`` package; they skip, saying why, where that browser is missing.
"""

from __future__ import annotations

import base64
import io
import json
import re
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import pytest
from PIL import Image
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.report import write_report
from sweep3d.report._build import THUMB_SIZE, script_json
from sweep3d.spec import load_spec
from tests.conftest import REPO, TINY_SPEC, write_spec

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-sync"]
ARTIFACTS = REPO / "test-artifacts"
DATA_URI = re.compile(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"')
SCRIPT = re.compile(r"<script\b[^>]*>.*?</script>", re.S | re.I)
EXTERNAL = re.compile(r"""(?:src|href)\s*=\s*["']?\s*(?:https?:)?//|url\(\s*["']?\s*(?:https?:)?//|@import""", re.I)

EVIL_OBJECT = "box<script>alert(1)</script>"
EVIL_ENV = "</script><img src=x onerror=alert(2)> & <b>bold</b>"
EVIL_EXPERIMENT = "tiny</title><script>alert(3)</script>"


def _failure_count(folder: Path) -> int:
    loaded = load_spec(folder / "spec.toml")
    con = Store(loaded.store).connect(loaded.name)
    return con.execute("SELECT count(*) FROM results WHERE valid AND NOT correct").fetchone()[0]


def test_report_is_self_contained(tiny_run: Path, tmp_path: Path) -> None:
    from plotly.offline import get_plotlyjs

    loaded = load_spec(tiny_run / "spec.toml")
    path = write_report(loaded)
    assert path == tiny_run / "store" / "reports" / "tiny.html"
    html = path.read_text(encoding="utf-8")

    markup = SCRIPT.sub("<script></script>", html)  # plotly.js names URLs in strings; markup must not
    assert not EXTERNAL.search(markup), EXTERNAL.search(markup)
    assert html.count("<script>") == 2  # plotly.js once, then the boot script; figures are JSON
    assert html.count('type="application/json"') >= 3
    assert "Content-Security-Policy" in html and "default-src &#39;none&#39;" in html
    assert len(html.encode()) < len(get_plotlyjs().encode()) + 400_000

    thumbs = DATA_URI.findall(markup)
    assert len(thumbs) == min(_failure_count(tiny_run), 48)
    for data in thumbs:
        with Image.open(io.BytesIO(base64.b64decode(data))) as img:
            assert img.format == "PNG" and max(img.size) <= THUMB_SIZE

    for text in ("tiny", "efficientnet-lite0", "orientation_yaw", "blur_sigma", "studio", "white", "box", "carton"):
        assert text in html

    elsewhere = write_report(loaded, tmp_path / "out" / "r.html")
    assert elsewhere == tmp_path / "out" / "r.html" and elsewhere.stat().st_size > 0
    assert not [p for p in elsewhere.parent.iterdir() if p.name.endswith(".tmp")]


def test_script_json_cannot_close_the_script_element() -> None:
    text = json.dumps({"name": "</script><script>alert(1)</script> & <!--"})
    safe = str(script_json(text))
    assert not set("<>&") & set(safe)
    assert json.loads(safe) == json.loads(text)


@contextmanager
def _page(path: Path) -> Iterator[tuple[Any, dict[str, list]]]:
    """A headless Chromium page showing ``path``, once plotly has drawn every figure."""
    if not CHROMIUM.exists():
        pytest.skip(f"headless Chromium not found at {CHROMIUM}; install it with: apt-get install chromium")
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1280, "height": 900})
            events: dict[str, list] = {"errors": [], "console": [], "requests": [], "dialogs": []}
            page.on("pageerror", lambda exc: events["errors"].append(str(exc)))
            page.on("console", lambda msg: events["console"].append(msg.text) if msg.type == "error" else None)
            page.on("request", lambda req: events["requests"].append(req.url))
            page.on("dialog", lambda dialog: (events["dialogs"].append(dialog.message), dialog.dismiss()))
            page.goto(path.as_uri())
            page.wait_for_function(
                "() => { const want = document.querySelectorAll('script.fig-data').length;"
                " const drawn = Array.from(document.querySelectorAll('.js-plotly-plot'))"
                "   .filter(d => d.querySelector('svg.main-svg')).length;"
                " return want > 0 && drawn === want; }",
                timeout=30_000,
            )
            page.wait_for_function(
                "() => Array.from(document.querySelectorAll('.failure img')).every(i => i.complete)",
                timeout=10_000,
            )
            yield page, events
        finally:
            browser.close()


def _assert_clean(path: Path, events: dict[str, list]) -> None:
    assert events["errors"] == []
    assert events["console"] == []
    assert events["dialogs"] == []
    assert events["requests"] == [path.as_uri()]  # nothing but the file itself


@pytest.mark.browser
def test_report_draws_in_chromium(tiny_run: Path) -> None:
    path = write_report(load_spec(tiny_run / "spec.toml"))
    failures = _failure_count(tiny_run)
    with _page(path) as (page, events):
        drawn = page.evaluate(
            "Array.from(document.querySelectorAll('.js-plotly-plot'))"
            ".filter(d => d.querySelector('svg.main-svg')).length"
        )
        assert drawn >= 3
        traces = page.evaluate(
            "Array.from(document.querySelectorAll('.js-plotly-plot')).flatMap(d => d.data.map(t => t.type))"
        )
        assert "heatmap" in traces and "bar" in traces
        assert page.evaluate("document.querySelectorAll('#fig-scenes .hm image').length") == 1
        assert page.evaluate("document.querySelectorAll('#controls .js-plotly-plot').length") == 2

        widths = page.evaluate("Array.from(document.querySelectorAll('.failure img')).map(i => i.naturalWidth)")
        assert len(widths) == min(failures, 48)
        assert all(w > 0 for w in widths)

        assert page.inner_text("#experiment") == "tiny"
        assert "box" in page.inner_text("#objects")

        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "report.png"), full_page=True)
        _assert_clean(path, events)


@pytest.mark.browser
def test_names_are_escaped(tiny_copy: Path) -> None:
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

    with _page(path) as (page, events):
        assert page.inner_text("#experiment") == EVIL_EXPERIMENT
        assert page.title().startswith(EVIL_EXPERIMENT)
        gallery = page.inner_text("#failures")
        if _failure_count(tiny_copy):
            assert EVIL_OBJECT in gallery and EVIL_ENV in gallery
        assert EVIL_OBJECT in page.inner_text("#objects")
        ticks = page.evaluate(
            "Array.from(document.querySelectorAll('#fig-scenes .xtick text, #fig-scenes .ytick text'))"
            ".map(t => t.textContent)"
        )
        assert EVIL_OBJECT in ticks and EVIL_ENV in ticks
        assert not page.evaluate("Array.from(document.querySelectorAll('b')).some(b => b.textContent === 'bold')")
        assert page.evaluate("document.querySelectorAll('img:not([src^=\"data:\"])').length") == 0
        assert page.evaluate("Array.from(document.scripts).filter(s => !s.type).length") == 2
        _assert_clean(path, events)


def test_report_on_an_empty_store_says_how_to_fix(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, TINY_SPEC)
    result = CliRunner().invoke(app, ["report", str(spec)])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    assert "no results for experiment 'tiny' yet" in lines[0]
    assert f"sweep3d run {spec}" in lines[0]
    assert not (tmp_path / "store" / "reports").exists()
