"""The static HTML report: one self-contained file (plotly.js, figures and thumbnails inlined).

Usage::

    from sweep3d.report import write_report
    path = write_report(load_spec("spec.toml"))  # <store>/reports/<experiment>.html
"""

from sweep3d.report._build import build_context, render_html, write_report

__all__ = ["build_context", "render_html", "write_report"]
