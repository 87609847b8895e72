"""Margins and fragile verdicts: how near a classification result is to the other verdict, and
whether changes no eye sees have been seen to flip verdicts that near.

``margin`` (a column of ``results`` for an evaluator that ranks classes) is the best true class's
probability minus the best other class's: positive when the top-1 class is a true one, negative for
a failure, 0 for a tie. It is computed from what every stored prediction already holds (the top-k
ids and probabilities, the label ids and ``label_prob``), so existing stores need nothing redone.
Where the top-k cannot say exactly, it is the bound nearest 0 (see :data:`MARGIN_MACRO`), so a
result is never called surer than it is.

``fragile`` comes from the stability check (``sweep3d stability``, rows in the store's
``stability`` table; per image and change its latest check): per model, the *threshold* is the
upper edge of the highest margin bin whose flip rate is at least :data:`FLIP_RATE` beyond
reasonable doubt (the lower end of its 95 % Wilson interval), so that one flip among a handful
of images does not make every margin below it fragile; a result is fragile when ``|margin|`` is
below it, or its own image flipped in the check. Without a check, ``fragile`` is
null (unknown), never false.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import duckdb
import pyarrow as pa
import pyarrow.parquet as pq

from sweep3d.results.quoting import identifier
from sweep3d.spec import DROP_FRAGILE_METADATA

#: Upper edges of the ``|margin|`` bins the stability check reports (the first bin starts at 0;
#: each bin is [previous edge, edge), the last also holds 1).
MARGIN_EDGES = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0)
#: The flip rate at which a margin bin's margins are fragile, once the lower end of its 95 % Wilson
#: interval reaches it: at 1 in 10, a verdict that near the other is a coin no eye sees could toss.
#: (Any single flip would call nearly every failure of a blurred sweep fragile: one of 40 images
#: flips even at margins 0.2–0.5.) An image that flipped is fragile whatever its bin's rate.
FLIP_RATE = 0.1
#: The prediction columns the margin is computed from (every evaluator that ranks classes has them).
MARGIN_INPUTS = ("topk", "topk_probs", "label_ids", "label_prob")

#: ``class_margin(topk, probs, ids, label_prob)``: the best true class's probability minus the best
#: other class's, from the stored top-k.
#:
#: - best true: the highest top-k probability of a true class; none in the top-k: ``label_prob``
#:   when the object has one label (exact), else ``least(label_prob, lowest top-k probability)``
#:   (an upper bound: each true class is below the top-k and below the set's sum); no label: 0.
#: - best other: the highest top-k probability of another class; every top-k class true:
#:   ``least(lowest top-k probability, 1 - label_prob)`` (an upper bound), never below 0.
#:
#: Both fallbacks move the margin towards 0, the conservative side for fragility. NULL when an
#: input is (an invalid prediction; DuckDB's greatest/least would skip a NULL); clamped to [-1, 1].
MARGIN_MACRO = """CREATE OR REPLACE MACRO class_margin(topk, probs, ids, label_prob) AS (
    CASE WHEN topk IS NULL OR probs IS NULL OR ids IS NULL OR label_prob IS NULL OR len(topk) = 0 THEN NULL
    ELSE greatest(-1.0, least(1.0,
        coalesce(
            list_max(list_transform(list_filter(list_zip(topk, probs), lambda x: list_contains(ids, x[1])),
                                    lambda x: x[2]::DOUBLE)),
            CASE WHEN len(ids) = 0 THEN 0.0
                 WHEN len(ids) = 1 THEN label_prob
                 ELSE least(label_prob, list_min(probs)::DOUBLE) END)
        - greatest(0.0, coalesce(
            list_max(list_transform(list_filter(list_zip(topk, probs), lambda x: NOT list_contains(ids, x[1])),
                                    lambda x: x[2]::DOUBLE)),
            least(list_min(probs)::DOUBLE, 1.0 - label_prob))))) END)"""


def create_margin_macro(con: duckdb.DuckDBPyConnection) -> None:
    con.execute(MARGIN_MACRO)


def margin_sql(columns: set[str] | dict[str, str], prefix: str = "p.") -> str | None:
    """The ``margin`` expression over a predictions relation with ``columns``; None when it lacks
    one of :data:`MARGIN_INPUTS` (an evaluator that does not rank classes)."""
    if not set(MARGIN_INPUTS) <= set(columns):
        return None
    args = ", ".join(f"{prefix}{identifier(c)}" for c in MARGIN_INPUTS)
    return f"class_margin({args})"


def bin_sql(value: str) -> str:
    """The bin index (0-based) of ``|value|`` among :data:`MARGIN_EDGES`."""
    cases = " ".join(f"WHEN abs({value}) < {edge!r}::DOUBLE THEN {i}" for i, edge in enumerate(MARGIN_EDGES[:-1]))
    return f"CASE {cases} ELSE {len(MARGIN_EDGES) - 1} END"


def _edges_sql() -> str:
    lows = (0.0, *MARGIN_EDGES[:-1])
    rows = ", ".join(f"({i}, {lo!r}::DOUBLE, {hi!r}::DOUBLE)" for i, (lo, hi) in enumerate(zip(lows, MARGIN_EDGES)))
    return f"(VALUES {rows}) e(bin, lower, upper)"


def register_fragile(con: duckdb.DuckDBPyConnection, drop: bool = False) -> bool:
    """Add ``fragile`` to ``results`` (all models' rows, before one is chosen) and the views of the
    stability check: ``stability_images`` (one row per checked image and model: its base margin
    and whether any change flipped it, an image change (``flipped_image``) or a scene neighbour
    (``flipped_scene``)), ``stability_bins`` (flip rate per margin bin, with Wilson intervals),
    ``stability_changes`` (the same per change), ``fragile_threshold`` (per model) and
    ``neighbourhood_accuracy`` (:data:`NEIGHBOURHOOD_SQL`). A scene neighbour's row (its
    ``neighbour_key`` set) counts as an image change's does: a flip under it is fragile.

    Args:
        drop: ``[aggregate] drop_fragile``: fragile results are not ``counted`` (the column
            ``counted_with_fragile`` keeps what was), so failure modes, boundaries and every
            accuracy leave them out.

    Returns:
        False when ``results`` has no ``margin`` (nothing added).
    """
    have = {row[0] for row in con.execute("DESCRIBE results").fetchall()}
    if "margin" not in have:
        return False
    checked = _has_relation(con, "stability")
    con.execute("ALTER VIEW results RENAME TO results_unjudged")
    model = "r.model" if "model" in have else "NULL::VARCHAR"
    # the latest check of each image and change: another --seed replaces its rows, never adds a chance to flip
    scene = ("s.neighbour_key IS NOT NULL" if checked and "neighbour_key" in _columns(con, "stability")
             else "false")  # a scene neighbour's row (sweep3d stability's re-rendered neighbours)
    source = (f"SELECT s.*, r.model, {scene} AS scene FROM stability s JOIN (SELECT DISTINCT pred_key, "
              f"{model} AS model FROM results_unjudged r) r USING (pred_key) QUALIFY row_number() OVER "
              "(PARTITION BY r.model, s.pred_key, s.change ORDER BY s.created_at DESC, s.stability_key DESC) = 1") \
        if checked else \
        ("SELECT NULL::VARCHAR AS model, NULL::VARCHAR AS pred_key, NULL::VARCHAR AS change, "
         "NULL::DOUBLE AS base_margin, NULL::BOOLEAN AS flipped, NULL::BOOLEAN AS base_correct, "
         "NULL::BOOLEAN AS correct, NULL::BOOLEAN AS scene WHERE false")
    con.execute(f"CREATE OR REPLACE VIEW stability_checks AS {source}")
    # the image rows' margin first: the check's own re-inference, as before scene rows existed
    con.execute("CREATE OR REPLACE VIEW stability_images AS SELECT *, "
                f"{bin_sql('base_margin')} AS bin FROM (SELECT model, pred_key, coalesce(any_value(base_margin) "
                "FILTER (WHERE NOT scene), any_value(base_margin)) AS base_margin, bool_or(flipped) AS flipped, "
                "bool_or(flipped) FILTER (WHERE NOT scene) AS flipped_image, "
                "bool_or(flipped) FILTER (WHERE scene) AS flipped_scene, "
                "count(*) FILTER (WHERE scene) AS neighbours FROM stability_checks GROUP BY model, pred_key)")
    con.execute(NEIGHBOURHOOD_SQL.format(model=model))
    for view, by, rows in (("stability_bins", "", "stability_images"),
                           ("stability_changes", "change, ",
                            f"(SELECT model, change, flipped, {bin_sql('base_margin')} AS bin FROM stability_checks)")):
        con.execute(
            f"CREATE OR REPLACE VIEW {view} AS SELECT m.model, {'m.change, ' if by else ''}e.bin, e.lower, e.upper, "
            "coalesce(c.n, 0) AS n, coalesce(c.flips, 0) AS flips, c.flips::DOUBLE / c.n AS flip_rate, "
            "wilson_low(c.flips, c.n) AS wilson_low, wilson_high(c.flips, c.n) AS wilson_high "
            f"FROM (SELECT DISTINCT model{', change' if by else ''} FROM {rows}) m CROSS JOIN {_edges_sql()} "
            f"LEFT JOIN (SELECT model, {by}bin, count(*) AS n, count(*) FILTER (WHERE flipped) AS flips "
            f"FROM {rows} GROUP BY ALL) c ON c.model IS NOT DISTINCT FROM m.model "
            f"{'AND c.change = m.change ' if by else ''}AND c.bin = e.bin ORDER BY ALL")
    con.execute("CREATE OR REPLACE VIEW fragile_threshold AS SELECT model, coalesce(max(upper) FILTER "
                f"(WHERE flips > 0 AND wilson_low >= {FLIP_RATE!r}), 0.0) AS threshold, sum(n)::BIGINT AS checked, "
                "sum(flips)::BIGINT AS flipped FROM stability_bins "
                "GROUP BY model")
    fragile = ("CASE WHEN t.threshold IS NULL OR r.margin IS NULL THEN NULL "
               "ELSE abs(r.margin) < t.threshold OR coalesce(i.flipped, false) END")
    on = "t.model IS NOT DISTINCT FROM r.model" if "model" in have else "true"
    on_image = " AND i.model IS NOT DISTINCT FROM r.model" if "model" in have else ""
    counted = (f", r.counted AND ({fragile}) IS NOT TRUE AS counted, r.counted AS counted_with_fragile"
               if drop and "counted" in have else "")
    con.execute(f"CREATE VIEW results AS SELECT r.*{' EXCLUDE (counted)' if counted else ''}, {fragile} AS fragile"
                f"{counted} FROM results_unjudged r LEFT JOIN fragile_threshold t ON {on} "
                f"LEFT JOIN stability_images i ON i.pred_key = r.pred_key{on_image}")
    return True


#: ``neighbourhood_accuracy``: per model and object (and over all objects: ``object`` NULL), over the
#: jobs whose scene neighbours were checked: plain accuracy (the job's own verdict) and
#: worst-of-neighbourhood accuracy (the job and every checked neighbour correct), each with its 95 %
#: Wilson interval. ``{model}``: the results' model column (NULL::VARCHAR for one model).
NEIGHBOURHOOD_SQL = """CREATE OR REPLACE VIEW neighbourhood_accuracy AS
WITH jobs AS (SELECT model, pred_key, any_value(base_correct) AS correct, bool_and(correct) AS all_correct,
                     count(*) AS neighbours, count(*) FILTER (WHERE flipped) AS flipped
              FROM stability_checks WHERE scene GROUP BY model, pred_key),
     objects AS (SELECT DISTINCT r.pred_key, {model} AS model, r.object FROM results_unjudged r),
     counted AS (SELECT j.model, o.object, count(*) AS images, sum(j.neighbours)::BIGINT AS neighbours,
                        count(*) FILTER (WHERE j.flipped > 0) AS flipped,
                        count(*) FILTER (WHERE j.correct) AS correct,
                        count(*) FILTER (WHERE j.correct AND j.all_correct) AS worst_correct
                 FROM jobs j JOIN objects o ON o.pred_key = j.pred_key AND o.model IS NOT DISTINCT FROM j.model
                 GROUP BY GROUPING SETS ((j.model, o.object), (j.model)))
SELECT model, object, images, neighbours, flipped, correct, correct::DOUBLE / images AS accuracy,
       wilson_low(correct, images) AS accuracy_low, wilson_high(correct, images) AS accuracy_high,
       worst_correct, worst_correct::DOUBLE / images AS worst_accuracy,
       wilson_low(worst_correct, images) AS worst_low, wilson_high(worst_correct, images) AS worst_high
FROM counted ORDER BY model, object NULLS LAST"""


def _columns(con: duckdb.DuckDBPyConnection, name: str) -> set[str]:
    return {row[0] for row in con.execute(f"DESCRIBE {identifier(name)}").fetchall()}


def _has_relation(con: duckdb.DuckDBPyConnection, name: str) -> bool:
    return bool(con.execute("SELECT count(*) FROM duckdb_views() WHERE view_name = ? AND NOT internal",
                            [name]).fetchone()[0])


def plan_drops_fragile(jobs: Path) -> bool:
    """Whether the plan at ``jobs`` was made from a spec with ``[aggregate] drop_fragile = true``."""
    try:
        return (pq.read_schema(jobs).metadata or {}).get(DROP_FRAGILE_METADATA) == b"true"
    except (OSError, ValueError, pa.ArrowException):
        return False


def fragile_sentence(summary: Any) -> str:
    """How many failures are fragile, for ``run``'s findings and the report; "" before any check."""
    if summary.fragile_failures is None or summary.fragile_threshold is None:
        return ""
    failures = summary.wrong + (summary.fragile_failures if summary.fragile_dropped else 0)
    share = f"1 in {round(1 / FLIP_RATE)}"
    rule = (f"|margin| < {summary.fragile_threshold:.3g}, where {share} checked images or more flip beyond doubt, or "
            "flipped in the check" if summary.fragile_threshold
            else f"flipped in the check; no margin bin flips {share} beyond doubt")
    dropped = (f"; [aggregate] drop_fragile: the {summary.fragile_dropped} fragile results, right or wrong, are left "
               "out of every count, accuracy, failure mode and boundary" if summary.fragile_dropped else "")
    return (f"fragile: {summary.fragile_failures} of {failures} failures ({rule}; stability check of "
            f"{summary.fragile_checked} images){dropped}")
