"""The static HTML report: one self-contained file (plotly.js, data and thumbnails inlined).

Panels (see :mod:`sweep3d.report.panels`): overall accuracy; the explorer (any parameter as a
heat-map axis, slider or pooled, computed in the browser; click a cell for its images); failure
modes (regions ranked by their Wilson interval); the worst failures; per object (sensitivity,
confusions); aggregate (accuracy per parameter with Wilson bands, box plots over scenes,
variance explained). Optional panels show only when their data exists.

Usage::

    from sweep3d.report import write_report
    from sweep3d.stages import load_spec
    path = write_report(load_spec("spec.toml"))  # <store>/reports/<experiment>.html
"""

from sweep3d.report._build import build_context, render_html, write_report

__all__ = ["build_context", "render_html", "write_report"]
