"""The report of 10 000 results: under 25 MB, and it works in headless Chromium.

The store is synthetic (``benchmarks/report_scale.py`` writes jobs and predictions as Parquet
rows and one small PNG per image); the time to interactive is measured by that benchmark, not
asserted here.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from benchmarks.report_scale import build_store
from sweep3d.report import write_report
from sweep3d.stages import load_spec
from tests.test_report import ARTIFACTS, assert_clean, cell_centre, open_page

RESULTS = 10_000
MAX_BYTES = 25_000_000


@pytest.fixture(scope="module")
def large_report(tmp_path_factory) -> Path:
    spec = build_store(tmp_path_factory.mktemp("scale") / "run", RESULTS)
    return write_report(load_spec(spec))


def test_report_of_10000_results_stays_under_25_mb(large_report: Path) -> None:
    size = large_report.stat().st_size
    assert size < MAX_BYTES, f"{size / 1e6:.1f} MB"
    html = large_report.read_text(encoding="utf-8")
    thumbs = json.loads(re.search(r'<script type="application/json" id="thumbs">(.*?)</script>', html, re.S).group(1))
    assert len(thumbs) == RESULTS and all(thumbs)  # every image embedded, none left out for size
    explorer = json.loads(re.search(r'<script type="application/json" id="explorer-data">(.*?)</script>', html,
                                    re.S).group(1))
    assert len(explorer["outcome"]) == RESULTS and all(len(levels) == RESULTS for levels in explorer["level"])


@pytest.mark.browser
def test_report_of_10000_results_works_in_chromium(large_report: Path) -> None:
    with open_page(large_report, wait_all=False) as (page, events):
        status = page.inner_text("#explorer-status")
        assert status.startswith(f"{RESULTS} valid results")
        page.mouse.click(*cell_centre(page, 0, 0))
        page.wait_for_selector("#explorer-gallery .tile")
        tiles = page.evaluate("document.querySelectorAll('#explorer-gallery .tile img').length")
        assert 0 < tiles <= 60
        assert "showing 60 of" in page.inner_text("#explorer-gallery")
        page.select_option("select[aria-label='role of orientation_yaw']", "slider")
        page.focus("input[aria-label='value of orientation_yaw']")
        page.keyboard.press("End")
        page.wait_for_function("() => document.querySelector('.explorer-control.slider output').textContent"
                               ".startsWith('144')")
        assert not page.inner_text("#explorer-status").startswith(f"{RESULTS} ")
        page.wait_for_function("() => document.documentElement.dataset.drawn === '1'", timeout=60_000)
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "scale-10000.png"), full_page=False)
        assert_clean(large_report, events)
