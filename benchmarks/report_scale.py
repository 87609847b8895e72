"""The report at scale: file size and time-to-interactive in headless Chromium.

Builds a synthetic store of N results (jobs and predictions written in bulk as Parquet
columns, a small textured PNG blob for each image the report embeds — test data shaped like a
run's output, not a stand-in for the renderer), writes the report, opens it in Chromium and
prints a table: file size, the explorer's joint-table cells and the images embedded, build
time, time to interactive (navigation start until the explorer and the figures on screen are
drawn), time until every figure is drawn, and the time a click on a heat-map cell takes to
fill the gallery and redraw the heat map.

    .venv/bin/python benchmarks/report_scale.py [--results 10000 100000 1000000] [--repeat 3]

:func:`build_store` is also used by the report's tests (``tests/report/test_report_scale.py``,
``tests/report/test_report_explorer.py``).
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import tempfile
import textwrap
import time
from pathlib import Path

from tests.helpers import build_store

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-sync"]





















# -- measurement ------------------------------------------------------------------------------
CELL_CENTRE = """() => {
  const gd = document.getElementById('explorer-plot'), box = gd.getBoundingClientRect();
  const xa = gd._fullLayout.xaxis, ya = gd._fullLayout.yaxis;
  return [box.left + xa._offset + xa.l2p(0), box.top + ya._offset + ya.l2p(0)];
}"""


def measure(spec: Path, repeat: int) -> dict[str, float]:
    """Build the report of ``spec`` and time it in Chromium (medians over ``repeat`` fresh pages)."""
    import sweep3d
    from sweep3d.report import write_report

    started = time.perf_counter()
    path = write_report(sweep3d.load(spec).spec)
    build = time.perf_counter() - started
    html = path.read_text(encoding="utf-8")
    explorer = json.loads(re.search(r'id="explorer-data">(.*?)</script>', html, re.S).group(1))
    thumbs = json.loads(re.search(r'id="thumbs">(.*?)</script>', html, re.S).group(1))
    return {"size_mb": path.stat().st_size / 1e6, "cells": explorer["cells"], "images": sum(map(bool, thumbs)),
            "build_s": build, **browse(path, repeat)}


def browse(path: Path, repeat: int) -> dict[str, float]:
    """Medians over ``repeat`` fresh pages: time to interactive, every figure drawn, a cell click."""
    from playwright.sync_api import sync_playwright

    ready, drawn, clicks = [], [], []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            for _ in range(repeat):
                page = browser.new_page(viewport={"width": 1280, "height": 900})
                page.goto(path.as_uri())
                page.wait_for_function("() => document.documentElement.dataset.drawn === '1'", timeout=120_000)
                ready.append(page.evaluate("window.sweep3d.readyAt") / 1000)
                drawn.append(page.evaluate("window.sweep3d.drawnAt") / 1000)
                page.mouse.click(*page.evaluate(CELL_CENTRE))
                page.wait_for_function("() => window.sweep3d.explorer.timings.click !== undefined")
                clicks.append(page.evaluate("window.sweep3d.explorer.timings.click") / 1000)
                page.close()
        finally:
            browser.close()
    return {"ready_s": statistics.median(ready), "drawn_s": statistics.median(drawn),
            "click_s": statistics.median(clicks)}


def main() -> None:
    from rich.console import Console
    from rich.table import Table

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    table = Table(title="sweep3d report at scale (headless Chromium)")
    for column in ("results", "store written", "file size", "explorer cells", "images embedded", "report build",
                   "time to interactive", "all figures drawn", "cell click → gallery"):
        table.add_column(column, justify="right")
    for results in args.results:
        with tempfile.TemporaryDirectory() as tmp:
            started = time.perf_counter()
            spec = build_store(Path(tmp) / "run", results)
            written = time.perf_counter() - started
            m = measure(spec, args.repeat)
        table.add_row(f"{results:,}", f"{written:.0f} s", f"{m['size_mb']:.1f} MB", f"{m['cells']:,}",
                      f"{m['images']:,}", f"{m['build_s']:.1f} s", f"{m['ready_s']:.2f} s", f"{m['drawn_s']:.2f} s",
                      f"{m['click_s'] * 1000:.0f} ms")
    Console().print(table)
    print(textwrap.dedent("""\
        time to interactive: navigation start until the explorer's heat map and the figures on screen are
        drawn (the rest are drawn as they come near, or one by one after that: "all figures drawn");
        medians over the loads. Store written: rows in bulk, and the report's images (found by building
        its panels once). Report build: reading the store, the panels, the thumbnails, writing the file."""))


if __name__ == "__main__":
    main()
