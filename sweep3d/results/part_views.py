"""``part_visibility``: accuracy conditioned on each part of an object's surface being visible.

The paper's Figure 8. Each render made with the UV pass records its pixels per part (the
``parts`` table, see :mod:`sweep3d.core.uv_cells`); a part counts as *visible* in an image when it
covers at least :data:`VISIBLE_SHARE` of the object's visible pixels (so a sliver on the
silhouette or a seam pixel does not count). Per (object, part): how many counted results show
the part, their accuracy with its Wilson interval, and the object's accuracy over all its
results with a UV pass, to compare against (``lift`` = the difference).
"""

from __future__ import annotations

import duckdb

from sweep3d.core import AZIMUTH_PARTS, ELEVATION_PARTS, PARTS_LAYOUT

VISIBLE_SHARE = 0.005  # of the object's visible pixels


def register_part_views(con: duckdb.DuckDBPyConnection, result_columns: set[str]) -> bool:
    """Create ``part_visibility`` when the store has UV-pass data and the results a parts key."""
    from sweep3d.results.views import has_view

    if "parts_key" not in result_columns or not has_view(con, "parts"):
        return False
    width, height = 360.0 / AZIMUTH_PARTS, 180.0 / ELEVATION_PARTS
    con.execute(f"""
        CREATE OR REPLACE VIEW part_visibility AS
        WITH shown AS (
            SELECT r.object, r.correct, p.parts, p.pixels, p.object_pixels
            FROM results r JOIN parts p USING (parts_key)
            WHERE r.counted AND p.layout = '{PARTS_LAYOUT}'),
        per_object AS (
            SELECT object, count(*) AS object_n, avg(correct::DOUBLE) AS object_accuracy FROM shown GROUP BY object),
        seen AS (
            SELECT object, correct, object_pixels, unnest(parts) AS part, unnest(pixels) AS pixels FROM shown),
        counted AS (
            SELECT object, part::INTEGER AS part, count(*) AS n, count(*) FILTER (WHERE correct) AS n_correct
            FROM seen WHERE pixels >= greatest(1, {VISIBLE_SHARE!r} * object_pixels)
            GROUP BY object, part)
        SELECT c.object, c.part,
               -180 + (c.part % {AZIMUTH_PARTS}) * {width!r} AS azimuth_from,
               -180 + (c.part % {AZIMUTH_PARTS} + 1) * {width!r} AS azimuth_to,
               -90 + (c.part // {AZIMUTH_PARTS}) * {height!r} AS elevation_from,
               -90 + (c.part // {AZIMUTH_PARTS} + 1) * {height!r} AS elevation_to,
               c.n, c.n_correct, c.n_correct / c.n AS accuracy,
               wilson_low(c.n_correct, c.n) AS wilson_low, wilson_high(c.n_correct, c.n) AS wilson_high,
               o.object_n, o.object_accuracy, c.n_correct / c.n - o.object_accuracy AS lift
        FROM counted c JOIN per_object o USING (object)
        ORDER BY c.object, c.part""")
    return True
