"""Views for what accuracy leaves out or lumps together: unevaluable jobs, and box and mask outcomes.

Each view is created only when the experiment has what it reads: ``not_evaluable`` a plan that
knows which jobs are in frame, the others an evaluator with an ``outcome`` or ``iou`` role (see
:class:`~sweep3d.core.evaluation.Roles`), so a classification experiment has none of those two,
whatever else its store holds:

``not_evaluable`` (needs ``ground_truth``: a plan with ``in_frame``)
    per (object, reason): ``n`` jobs with ``evaluable = false``, ``object_jobs`` (all the
    object's jobs), ``share`` of them, and ``min_visible`` (the plan's threshold; null without
    truth passes). ``reason`` is ``out of frame`` (the planner put the object outside the frame,
    it reaches behind the camera, so no visible fraction, or no pixel of it would reach the image
    even unoccluded: the truth row's ``framed_pixels`` is 0), ``fully occluded`` (in frame, and
    no pixel of it visible: something in front hides all of it; a truth row from before
    ``framed_pixels`` cannot tell this from a frame's edge that cuts all of it off) or
    ``hidden`` (some of it is in the image, but less than ``min_visible`` of its silhouette:
    occluded or mostly clipped). Jobs out of frame are never rendered, so they are counted from
    the plan, not from ``results``.
``outcomes_by_value`` (the ``outcome`` role: box and mask tasks)
    per (parameter, level) as in ``control_accuracy``: ``n`` counted results with an outcome,
    ``n_<outcome>`` and ``share_<outcome>`` for each of :data:`OUTCOMES` (the shares sum to 1).
``iou_by_object`` (the ``iou`` role)
    per object: ``n`` counted results, ``misses`` (no box or mask found on the object: IoU 0),
    the IoU's ``mean`` and quantiles ``p10``, ``p25``, ``median``, ``p75``, ``p90`` (linear
    interpolation, as numpy's default), misses counted as 0.
"""

from __future__ import annotations

import duckdb

from sweep3d.core import OUTCOMES, Roles  # what a box or mask task says (``results.outcome``)
from sweep3d.results.measures import NOT_A_MEASURE
from sweep3d.results.quoting import literal

TASK_VIEWS = ("not_evaluable", "outcomes_by_value", "iou_by_object")
#: Why a job is not evaluable (``not_evaluable.reason``).
OUT_OF_FRAME, OCCLUDED, HIDDEN = "out of frame", "fully occluded", "hidden"
QUANTILES = {"p10": 0.1, "p25": 0.25, "median": 0.5, "p75": 0.75, "p90": 0.9}


def register_task_views(con: duckdb.DuckDBPyConnection, roles: Roles, result_columns: set[str],
                        model: str | None = None, min_visible: float | None = None) -> list[str]:
    """Create those of :data:`TASK_VIEWS` the experiment has; returns their names.

    Args:
        roles: the roles of the experiment's evaluator.
        result_columns: the columns of ``results``.
        model: the model ``results`` shows when the jobs table holds several (its jobs are counted).
        min_visible: the plan's ``[evaluator] min_visible`` (shown only for a plan with truth passes).
    """
    from sweep3d.results.views import has_view

    made = []
    if "evaluable" in result_columns and has_view(con, "ground_truth"):
        con.execute(_not_evaluable_sql(con, model, min_visible))
        made.append("not_evaluable")
    if roles.has("outcome"):
        con.execute(_outcomes_sql())
        made.append("outcomes_by_value")
    if roles.has("iou"):
        con.execute(_iou_sql(roles.iou))
        made.append("iou_by_object")
    return made


def _not_evaluable_sql(con: duckdb.DuckDBPyConnection, model: str | None, min_visible: float | None) -> str:
    jobs = {row[0] for row in con.execute("DESCRIBE jobs").fetchall()}
    own = " AND g.model = j.model" if "model" in jobs else ""
    where = f" WHERE j.model = {literal(model)}" if model is not None and "model" in jobs else ""
    known = min_visible is not None and "truth_key" in jobs  # without truth passes, no threshold applies
    threshold = f"{float(min_visible)!r}::DOUBLE" if known else "NULL::DOUBLE"
    framed, framing = _framed_pixels(con)
    return f"""CREATE OR REPLACE VIEW not_evaluable AS
        WITH planned AS (
            SELECT j.object, j.in_frame, g.evaluable, g.visible_pixels, g.visible_fraction, {framed} AS framed_pixels
            FROM jobs j JOIN ground_truth g ON g.job = j.job{own}{framing}{where}),
        per_object AS (SELECT object, count(*) AS object_jobs FROM planned GROUP BY object)
        SELECT object, reason, n, object_jobs, n / object_jobs AS share, {threshold} AS min_visible
        FROM (SELECT object, CASE WHEN NOT in_frame OR visible_fraction IS NULL OR framed_pixels = 0 THEN '{OUT_OF_FRAME}'
                                  WHEN coalesce(visible_pixels, 0) = 0 THEN '{OCCLUDED}'
                                  ELSE '{HIDDEN}' END AS reason, count(*) AS n
              FROM planned WHERE evaluable = false GROUP BY ALL)
        JOIN per_object USING (object)
        ORDER BY object, reason"""


def _framed_pixels(con: duckdb.DuckDBPyConnection) -> tuple[str, str]:
    """The column of ``framed_pixels`` (the unoccluded silhouette's pixels in the image, which
    tells a wholly occluded object from one the frame's edge cuts off) and the join that brings
    it; NULL where the store's truth rows are all from before it."""
    try:
        columns = {row[0] for row in con.execute("DESCRIBE truths").fetchall()}
    except duckdb.CatalogException:  # a store without truth rows
        columns = set()
    if "framed_pixels" not in columns:
        return "NULL::BIGINT", ""
    return "t.framed_pixels", " LEFT JOIN (SELECT truth_key, framed_pixels FROM truths) t ON t.truth_key = g.truth_key"


def _outcomes_sql() -> str:
    counts = ", ".join(f"count(*) FILTER (WHERE l.counted AND r.outcome = '{o}') AS n_{o}" for o in OUTCOMES)
    shares = ", ".join(f"n_{o} / nullif(n, 0) AS share_{o}" for o in OUTCOMES)
    return f"""CREATE OR REPLACE VIEW outcomes_by_value AS
        SELECT parameter, position, level, label, n, {", ".join(f"n_{o}" for o in OUTCOMES)}, {shares} FROM (
            SELECT l.parameter, l.position, l.level, any_value(l.label) AS label,
                   count(*) FILTER (WHERE l.counted AND r.outcome IS NOT NULL) AS n, {counts}
            FROM control_levels l JOIN results r USING (job) WHERE l.{NOT_A_MEASURE}
            GROUP BY l.parameter, l.position, l.level)
        ORDER BY position, level"""


def _iou_sql(column: str) -> str:
    # A counted result without an IoU found no box (or mask) on the object: IoU 0, not left out,
    # or an object the model mostly misses looks best, its few found boxes being good ones.
    levels = ", ".join(repr(q) for q in QUANTILES.values())
    picked = ", ".join(f"q[{i}] AS {name}" for i, name in enumerate(QUANTILES, 1))
    return f"""CREATE OR REPLACE VIEW iou_by_object AS
        SELECT object, n, misses, mean, {picked} FROM (
            SELECT object, count(*) AS n, count(*) FILTER (WHERE missed) AS misses, avg(iou) AS mean,
                   quantile_cont(iou, [{levels}]) AS q
            FROM (SELECT object, coalesce("{column}", 0) AS iou, "{column}" IS NULL AS missed
                  FROM results WHERE counted)
            WHERE isfinite(iou) GROUP BY object)
        ORDER BY object"""
