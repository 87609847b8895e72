"""Progress when the output is not a terminal: plain lines at a steady interval, and each stage's last."""

from __future__ import annotations

import io
import time

from rich.console import Console

from sweep3d.driver.progress import RunProgress


def test_a_piped_run_prints_plain_progress_lines_while_it_works() -> None:
    out = io.StringIO()
    console = Console(file=out, force_terminal=False, width=200)
    with RunProgress(console, every=0.05) as progress:
        with progress.stage("render", total=10, cached=2) as bar:
            bar.advance(3)
            time.sleep(0.3)
            bar.advance(1, failed=True)
    lines = out.getvalue().splitlines()
    assert len(lines) >= 3, lines  # some while working, then the last one
    assert all(line.startswith("render: ") for line in lines) and "\x1b" not in out.getvalue()
    # the cached keys count as done from the start: never fewer done than cached (issue 45)
    assert lines[0].startswith("render: 5/12 (2 cached, 0 failed), ") and "left" in lines[0]
    assert lines[-1].startswith("render: 6/12 (2 cached, 1 failed), ") and "elapsed" in lines[-1]


def test_a_stage_with_nothing_computed_yet_counts_its_cached_keys_done() -> None:
    """``render: 0/14 (14 cached …)`` then ``14/14 (14 cached)`` read as contradictions: the count
    starts at the cached keys, and the rate and time left are of computed ones only."""
    out = io.StringIO()
    console = Console(file=out, force_terminal=False, width=200)
    with RunProgress(console, every=0.05) as progress:
        with progress.stage("render", total=14, cached=14) as bar:
            time.sleep(0.2)
            bar.advance(14)
    lines = out.getvalue().splitlines()
    assert lines[0] == "render: 14/28 (14 cached, 0 failed)"  # nothing computed: no rate yet
    rate = float(lines[-1].split(", ")[2].removesuffix("/s"))
    elapsed = 0.2
    assert lines[-1].startswith("render: 28/28 (14 cached, 0 failed), ") and rate < 14 / elapsed + 1e-9


def test_a_terminal_gets_bars_and_no_plain_lines() -> None:
    out = io.StringIO()
    console = Console(file=out, force_terminal=True, width=120)
    with RunProgress(console, every=0.01) as progress:
        with progress.stage("infer", total=2, cached=0) as bar:
            bar.advance(2)
            time.sleep(0.05)
    assert "infer: 2/2" not in out.getvalue() and "2/2" in out.getvalue()
