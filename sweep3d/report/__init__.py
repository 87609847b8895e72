"""The static HTML report: one self-contained file (plotly.js, data and thumbnails inlined).

Panels (see :mod:`sweep3d.report.panels`): overall accuracy; the explorer (any parameter as a
heat-map axis, slider or pooled, summed in the browser from the counts of every combination of
levels the page carries; click a cell for its sampled images); failure modes (regions ranked
by their Wilson interval); the worst failures; per object (sensitivity, confusions); aggregate
(accuracy per parameter with Wilson bands, box plots over scenes, variance explained). Optional panels show only when their data exists. The page's size is
bounded by the numbers of parameter levels, not of results (a bounded sample of thumbnails,
counts instead of rows).

Usage::

    from sweep3d.report import write_report
    from sweep3d.stages import load_spec
    path = write_report(load_spec("spec.toml"))  # <store>/reports/<experiment>.html
"""

from sweep3d.report._build import build_context, image_keys, render_html, write_report

__all__ = ["build_context", "image_keys", "render_html", "write_report"]
