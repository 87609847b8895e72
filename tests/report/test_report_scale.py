"""The report of 10 000 results: it carries counts and a bounded sample, not one row per result,
and it works in headless Chromium.

The store is synthetic (``benchmarks/report_scale.py`` writes jobs and predictions as Parquet
rows in bulk, and image blobs for the images the report embeds); the size and time to
interactive at 10^4, 10^5 and 10^6 results are measured by that benchmark, not asserted here.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from sweep3d.cache.store import Store
from sweep3d.report import write_report
from sweep3d.report.panels.explorer import GALLERY_LIMIT
from sweep3d.report.thumbs import MAX_IMAGES
from sweep3d.results import connect
from tests.helpers import ARTIFACTS, assert_clean, build_store, cell_centre, load_spec, open_page, page_thumbnails

RESULTS = 10_000
MAX_BYTES = 25_000_000


@pytest.fixture(scope="module")
def large_report(tmp_path_factory) -> Path:
    spec = build_store(tmp_path_factory.mktemp("scale") / "run", RESULTS)
    return write_report(load_spec(spec))


def explorer_data(html: str) -> dict:
    return json.loads(re.search(r'<script type="application/json" id="explorer-data">(.*?)</script>', html,
                                re.S).group(1))


def test_report_of_10000_results_carries_counts_and_a_bounded_sample(large_report: Path) -> None:
    size = large_report.stat().st_size
    assert size < MAX_BYTES, f"{size / 1e6:.1f} MB"
    html = large_report.read_text(encoding="utf-8")
    thumbs = page_thumbnails(html)
    assert len(thumbs) <= MAX_IMAGES and all(thumbs)  # a sample, every image of it embedded
    explorer = explorer_data(html)
    levels = math.prod(len(p["labels"]) for p in explorer["params"])
    assert explorer["mode"] == "joint" and len(explorer["tables"][0]["n"]) == explorer["cells"] <= levels
    assert sum(explorer["tables"][0]["total"]) == RESULTS
    assert len(explorer["sample"]["job"]) <= MAX_IMAGES
    assert f"of {RESULTS} images embedded" in html


@pytest.mark.browser
def test_report_of_10000_results_works_in_chromium(large_report: Path, chromium) -> None:
    loaded = load_spec(large_report.parents[2] / "spec.toml")
    con = connect(Store(loaded.store), loaded.name)
    valid, total = con.execute("SELECT count(*) FILTER (WHERE valid), count(*) FROM results WHERE object = "
                               "'basketball' AND environment = 'city'").fetchone()
    with open_page(chromium, large_report, wait_all=False) as (page, events):
        everything = con.execute("SELECT count(*) FROM results WHERE valid").fetchone()[0]
        assert page.inner_text("#explorer-status").startswith(f"{everything} valid results")
        page.mouse.click(*cell_centre(page, 0, 0))  # basketball in the city
        page.wait_for_selector("#explorer-gallery .tile")
        tiles = page.evaluate("document.querySelectorAll('#explorer-gallery .tile img').length")
        assert tiles == GALLERY_LIMIT
        note = page.inner_text("#explorer-gallery .note")
        assert f" of {valid} correct" in note and f"showing {GALLERY_LIMIT} of {total}" in note
        assert re.search(r"· \d+ more not embedded in this page", note)
        listing = page.inner_text("#explorer-gallery .listing code")
        assert listing.startswith(f"sweep3d query {loaded.path} ")
        assert len(con.execute(listing.split('"', 1)[1].rsplit('"', 1)[0]).fetchall()) == total  # lists them all

        page.select_option("select[aria-label='role of orientation_yaw']", "slider")
        page.focus("input[aria-label='value of orientation_yaw']")
        page.keyboard.press("End")
        page.wait_for_function("() => document.querySelector('.explorer-control.slider output').textContent"
                               ".startsWith('144')")
        assert not page.inner_text("#explorer-status").startswith(f"{everything} ")
        page.wait_for_function("() => document.documentElement.dataset.drawn === '1'", timeout=60_000)
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "scale-10000.png"), full_page=False)
        assert_clean(large_report, events)
