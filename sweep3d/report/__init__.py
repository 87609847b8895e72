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
    import sweep3d
    path = write_report(sweep3d.load("spec.toml").spec)  # <store>/reports/<experiment>.html
"""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.report._build import build_context, image_keys, render_html, write_report
    from sweep3d.report.sheet import contact_sheet

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
