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
    assert lines[0].startswith("render: 3/10 (2 cached, 0 failed), ") and "left" in lines[0]
    assert lines[-1].startswith("render: 4/10 (2 cached, 1 failed), ") and "elapsed" in lines[-1]


def test_a_terminal_gets_bars_and_no_plain_lines() -> None:
    out = io.StringIO()
    console = Console(file=out, force_terminal=True, width=120)
    with RunProgress(console, every=0.01) as progress:
        with progress.stage("infer", total=2, cached=0) as bar:
            bar.advance(2)
            time.sleep(0.05)
    assert "infer: 2/2" not in out.getvalue() and "2/2" in out.getvalue()
