"""The ``sweep3d`` command line: plan, run, report, query."""

from __future__ import annotations

from sweep3d.cli.app import app, console_main, main  # eager: the command line is what importing this package is for

__all__ = ["app", "console_main", "main"]
