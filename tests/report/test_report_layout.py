"""The report's layout at a laptop's width (1,366 and 1,440 px): the failure-modes table is compact.

Each failure mode's examples are a strip of small tiles beside its numbers; they were a column
of 96-pixel tiles, which made each row about 500 px tall with most of its width empty. The store
is synthetic (``benchmarks/report_scale.py``: 2,000 results, six failure modes with four examples
each); screenshots of the page and the panel go to ``test-artifacts/``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from sweep3d.report import write_report
from sweep3d.report.panels.failure_modes import EXAMPLES
from tests.helpers import ARTIFACTS, assert_clean, build_store, load_spec, open_page

RESULTS = 2_000
ROW_HEIGHT = 140  # px: a row of numbers beside four thumbnails
PANEL_HEIGHT = 1_500  # px: the failure-modes panel of six rows (3,675 px with stacked examples)
PAGE_HEIGHT = 11_500  # px: the whole report of this store (12,885 px with stacked examples)

ROWS = "Array.from(document.querySelectorAll('#failure-modes table.modes:not(.muted) tbody tr'))"
TILE_BOXES = ROWS + (".map(r => Array.from(r.querySelectorAll('td:last-child .tile'))"
                     ".map(t => { const b = t.getBoundingClientRect(); return [b.left, b.top, b.right]; }))")


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    return write_report(load_spec(build_store(tmp_path_factory.mktemp("layout") / "run", RESULTS)))


def assert_side_by_side(tiles: list[list[float]]) -> None:
    """One line of tiles, left to right, none overlapping."""
    assert len({round(top) for _, top, _ in tiles}) == 1, tiles
    assert all(right <= left for (_, _, right), (left, _, _) in zip(tiles, tiles[1:])), tiles


@pytest.mark.browser
@pytest.mark.parametrize("width", [1366, 1440])
def test_failure_modes_rows_are_compact_at_a_laptops_width(report: Path, chromium, width: int) -> None:
    with open_page(chromium, report, width=width) as (page, events):
        heights = page.evaluate(ROWS + ".map(r => r.getBoundingClientRect().height)")
        tiles = page.evaluate(TILE_BOXES)
        assert len(heights) >= 4 and all(len(row) == EXAMPLES for row in tiles), tiles
        assert max(heights) < ROW_HEIGHT, heights
        for row in tiles:
            assert_side_by_side(row)
        panels = page.evaluate("Object.fromEntries(Array.from(document.querySelectorAll('section'))"
                               ".map(s => [s.id, s.getBoundingClientRect().height]))")
        assert panels["failure-modes"] < PANEL_HEIGHT, panels
        assert page.evaluate("document.documentElement.scrollHeight") < PAGE_HEIGHT, panels
        assert page.evaluate("document.documentElement.scrollWidth") == width  # nothing runs off the side
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / f"layout-{width}.png"), full_page=True)
        page.locator("#failure-modes").screenshot(path=str(ARTIFACTS / f"layout-{width}-failure-modes.png"))
        assert_clean(report, events)
