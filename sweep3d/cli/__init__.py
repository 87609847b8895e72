"""The ``sweep3d`` command line: plan, run, report, query."""

from sweep3d.cli.app import app, main

__all__ = ["app", "main"]
