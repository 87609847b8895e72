"""Average precision (COCO's) of a detector, overall and per control level, as SQL views.

Created only for an evaluator with the detection roles (``detection_scores``/``detection_ious``,
which ``results`` shows as ``det_scores``/``det_ious``: see
:mod:`sweep3d.stages.infer.evaluators.detection`). Every image holds one object, whose
label set is its class, so COCO's "per class" is here per object:

- the *positives* of an object are its evaluable, valid results (``evaluable IS NOT FALSE AND
  valid``), one true box each;
- its *detections* are every entry of their ``det_scores``/``det_ious`` (each matching
  detection, whatever its score);
- at an IoU threshold t, the highest-scoring detection of an image with IoU ≥ t is a true
  positive, every other detection a false positive;
- the detections are ranked by score, descending (ties: by job, then by rank within the image);
  precision is made monotone (the best precision at any recall at least as high), and AP is its
  mean over the 101 recall points 0, 0.01, …, 1 (0 at a recall never reached). The recall
  points are compared in integers (``100 · true positives ≥ r · positives``), so no rounding
  decides whether a point is reached.

Views:

``average_precision``
    object (NULL: the mean over objects, i.e. mAP), images (positives), ap50, ap75 and ap (the
    mean over t = 0.50, 0.55, …, 0.95).
``average_precision_by_value``
    the same per level of each parameter, named as ``control_levels`` names them: parameter,
    position, level, label, then object, images, ap50, ap75, ap. Each level has a row per object
    seen at that level and a mean row (object NULL) over those objects, the one to plot against
    the level; the per-object rows say which object drives it. A level's images are those of
    its results, so a level with few images has a noisy AP.
"""

from __future__ import annotations

import duckdb

from sweep3d.core import Roles
from sweep3d.results.measures import NOT_A_MEASURE

DETECTION_VIEWS = ("average_precision", "average_precision_by_value")
THRESHOLDS = 10  # t = 0.50, 0.55, …, 0.95
RECALL_POINTS = 101

_LEVEL_KEYS = ("parameter", "position", "level", "label")


def detection_views(con: duckdb.DuckDBPyConnection, roles: Roles, result_columns: set[str]) -> bool:
    """Create the average-precision views for an evaluator with the detection roles (after ``control_levels``)."""
    if not (roles.has("detection_scores") and {"object", "job", "valid"} <= result_columns):
        return False
    evaluable = "r.valid AND r.evaluable IS NOT FALSE" if "evaluable" in result_columns else "r.valid"
    con.execute("CREATE OR REPLACE VIEW average_precision AS "
                + ap_sql(f"(SELECT r.object, r.job, r.det_scores, r.det_ious FROM results r WHERE {evaluable})", ()))
    by_value = ("(SELECT l.parameter, l.position, l.level, l.label, r.object, r.job, r.det_scores, r.det_ious "
                f"FROM control_levels l JOIN results r USING (job) WHERE {evaluable} AND l.{NOT_A_MEASURE})")
    con.execute("CREATE OR REPLACE VIEW average_precision_by_value AS " + ap_sql(by_value, _LEVEL_KEYS))
    return True


def ap_sql(source: str, keys: tuple[str, ...]) -> str:
    """A SELECT of AP per (``keys``, object) and its mean over objects per ``keys`` (object NULL).

    Args:
        source: a relation of the positives: ``keys``, object, job, det_scores, det_ious.
        keys: the columns that group the positives besides the object (none: the whole table).
    """
    k = "".join(f"{key}, " for key in keys)
    group = k + "object"
    return f"""
        WITH positive AS MATERIALIZED (SELECT {group}, job, det_scores, det_ious FROM {source}),
        positives AS (SELECT {group}, count(*) AS images FROM positive GROUP BY {group}),
        thresholds AS (SELECT step, (50 + 5 * step) / 100 AS t FROM range({THRESHOLDS}) s(step)),
        detections AS MATERIALIZED (
            SELECT {group}, job, score::DOUBLE AS score, iou::DOUBLE AS iou, nth
            FROM (SELECT {group}, job, unnest(det_scores) AS score, unnest(det_ious) AS iou,
                         unnest(range(len(det_scores))) AS nth
                  FROM positive)),
        judged AS (
            SELECT d.*, th.step,
                   coalesce(d.iou >= th.t, false)
                   AND row_number() OVER (PARTITION BY {group}, job, th.step, coalesce(d.iou >= th.t, false)
                                          ORDER BY d.score DESC, d.nth) = 1 AS tp
            FROM detections d, thresholds th),
        ranked AS (
            SELECT {group}, step, tp, sum(tp::INTEGER) OVER w AS tp_count, row_number() OVER w AS rank
            FROM judged
            WINDOW w AS (PARTITION BY {group}, step ORDER BY score DESC, job, nth ROWS UNBOUNDED PRECEDING)),
        envelope AS (
            SELECT *, max(tp_count / rank) OVER (PARTITION BY {group}, step ORDER BY rank DESC
                                                 ROWS UNBOUNDED PRECEDING) AS precision
            FROM ranked),
        -- Recall first reaches `need` true positives at the true positive that makes them `need`;
        -- recall 0 is reached at the first rank.
        reached AS (
            SELECT {group}, step, tp_count AS need, precision FROM envelope WHERE tp
            UNION ALL
            SELECT {group}, step, 0 AS need, precision FROM envelope WHERE rank = 1),
        points AS (
            SELECT {group}, images, step, (r * images + {RECALL_POINTS - 2}) // {RECALL_POINTS - 1} AS need
            FROM positives, thresholds, range({RECALL_POINTS}) p(r)),
        per_step AS (
            SELECT {group}, any_value(images) AS images, step,
                   sum(coalesce(precision, 0)) / {RECALL_POINTS} AS ap
            FROM points LEFT JOIN reached USING ({group}, step, need)
            GROUP BY {group}, step),
        per_object AS (
            SELECT {group}, any_value(images) AS images,
                   any_value(ap) FILTER (WHERE step = 0) AS ap50, any_value(ap) FILTER (WHERE step = 5) AS ap75,
                   avg(ap) AS ap
            FROM per_step GROUP BY {group})
        SELECT {group}, images, ap50, ap75, ap FROM per_object
        UNION ALL
        SELECT {k}NULL::VARCHAR AS object, sum(images)::BIGINT AS images, avg(ap50), avg(ap75), avg(ap)
        FROM per_object {f"GROUP BY {', '.join(keys)}" if keys else ""} HAVING count(*) > 0
        ORDER BY {k}object NULLS FIRST"""
