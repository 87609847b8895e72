"""``ground_truth``, ``results`` and ``counted``: what every number of the views, the summary and
the report is computed from, defined once, above the storage layer.

The store (:meth:`sweep3d.cache.store.Store.connect`) gives a view per table and the
experiment's ``jobs``; this module joins them by the rules of evaluation:

``ground_truth``
    per job of the plan (and model): its truth columns and ``evaluable``: false for a job out of
    frame and, where the plan has truth passes, for one whose ``visible_fraction`` is below
    ``[evaluator] min_visible`` (null while its truth row is missing); without truth passes it
    is ``in_frame``.
``results``
    jobs ⨝ predictions ⨝ ground_truth, with *the experiment's evaluator's* columns only (the
    plan records which: :class:`~sweep3d.core.evaluation.EvaluatorRecord`), so a store shared with
    another task's experiment adds none of its columns; each role's column also under its usual
    name (``correct``, ``loss``, ``outcome``, ``top1_label``, …). Class names are the spec's where
    it names a class otherwise than the model, the model's own beside them (``top1_model_label``,
    ``topk_model_labels``; :mod:`~sweep3d.results.class_name_views`). ``counted``
    (:data:`COUNTED_SQL`) is what every accuracy counts: a valid prediction of a job not known to
    be unevaluable.
``evaluator``
    the experiment's evaluator: its ``kind`` and each ``role`` with its ``column`` (what the
    views, the summary and the report choose their panels by; :func:`results_roles` reads it).

A plan from before plans recorded their evaluator (or a jobs file written by hand) gets the
predictions' columns and the roles their names suggest (:meth:`Roles.guess`).
"""

from __future__ import annotations

import json
from pathlib import Path

import duckdb
import pyarrow as pa
import pyarrow.parquet as pq

from sweep3d.core import EvaluatorRecord, Roles, read_record
from sweep3d.results.class_name_views import named_columns, read_class_names
from sweep3d.results.fragile import create_margin_macro, margin_sql
from sweep3d.results.quoting import identifier, literal
from sweep3d.spec import (
    MIN_VISIBLE_METADATA,
    MIN_VISIBLE_OFF,
    MODEL_NAME_COLUMNS,
    PREDICTION_COLUMNS,
    PROTOCOL_METADATA,
)

DEFAULT_MIN_VISIBLE = 0.1
#: ``results.counted``: the rows every accuracy averages. A prediction must be valid (finite
#: outputs) and its job not known to be unevaluable (out of frame, or too little of the object
#: visible): such a job is counted apart, never as a failure. Unknown (no truth row yet) counts.
COUNTED_SQL = "p.{valid} AND g.evaluable IS NOT FALSE"
#: The ``kind`` of a plan that recorded no evaluator.
UNRECORDED = "(not recorded)"


def register_results(con: duckdb.DuckDBPyConnection, jobs: Path, truths: bool) -> EvaluatorRecord | None:
    """Create ``ground_truth``, ``results`` and ``evaluator`` on ``con`` (which has the store's
    ``jobs`` view, of the plan at ``jobs``, and its ``predictions`` view when there are any).

    Args:
        truths: the store has a ``truths`` view.

    Returns:
        the experiment's evaluator (roles guessed for an unrecorded one); None when there are
        no predictions yet (then there is no ``results``).
    """
    truth = _ground_truth_sql(con, jobs, truths)
    if truth is not None:
        con.execute(truth)
    if not _has(con, "predictions"):
        return None
    have = _columns(con, "predictions")
    record = read_record(jobs) or EvaluatorRecord(
        UNRECORDED, tuple(c for c in have if c not in PREDICTION_COLUMNS), Roles.guess(set(have)))
    job_columns = _columns(con, "jobs")
    # A job row names its model (a spec may test several); a prediction row is shared by every
    # experiment whose job has its key, so its own ``model`` is what the first called it.
    own = "model" in job_columns
    kept = [c for c in ("model", "model_digest", "seconds") if c in have and not (c == "model" and own)]
    # Class names as the spec wrote them (the model's own beside them): see results.class_name_views.
    named = named_columns(have, record.columns, record.roles.prediction, read_class_names(jobs), own)
    picked = [f"{named.get(c, f'p.{identifier(c)}')} AS {identifier(c)}" if c in have else f"NULL AS {identifier(c)}"
              for c in record.columns]
    picked += [f"{named.get(usual, f'p.{identifier(column)}')} AS {identifier(usual)}"
               for usual, column in record.roles.aliases().items() if usual != column and column in have]
    picked += [f"{named[c]} AS {identifier(c)}" for c in MODEL_NAME_COLUMNS.values()
               if c in named and c not in record.columns]
    margin = margin_sql(set(have) & set(record.columns)) if "margin" not in record.columns else None
    if margin is not None:  # the best true class's probability less the best other's (results.fragile)
        create_margin_macro(con)
        picked.append(f"{margin} AS margin")
    valid = record.roles.valid
    counted = (COUNTED_SQL.format(valid=identifier(valid)) if truth is not None else f"p.{identifier(valid)}") \
        if valid in have else None
    exclude = ", model" if own else ""
    con.execute(
        "CREATE VIEW results AS SELECT j.*" + "".join(f", p.{identifier(c)}" for c in kept)
        + "".join(f", {c}" for c in picked)
        + (f", g.* EXCLUDE (job, truth_key{exclude})" if truth is not None else "")
        + (f", {counted} AS counted" if counted else "")
        + " FROM jobs j JOIN predictions p USING (pred_key)"
        + (" LEFT JOIN ground_truth g ON g.job = j.job" + (" AND g.model = j.model" if own else "")
           if truth is not None else "")
    )
    roles = "".join(f", ({literal(role)}, {literal(column)})" for role, column in record.roles.columns().items())
    con.execute(f"CREATE VIEW evaluator AS SELECT {literal(record.kind)} AS kind, role, \"column\" "
                f"FROM (VALUES {roles[2:]}) t(role, \"column\")")
    return record


def results_roles(con: duckdb.DuckDBPyConnection) -> Roles:
    """The roles of the experiment's evaluator, from the ``evaluator`` view; for a ``results``
    view made by hand (no such view), the roles its column names suggest."""
    if _has(con, "evaluator"):
        return Roles(**dict(con.execute('SELECT role, "column" FROM evaluator').fetchall()))
    return Roles.guess(set(_columns(con, "results")) if _has(con, "results") else set())


def plan_min_visible(jobs: Path) -> float | None:
    """``[evaluator] min_visible`` as the plan at ``jobs`` recorded it (the default when it did not,
    or recorded something unusable): the threshold ``evaluable`` applies; None where the plan has
    truth passes only for a control (no gate: ``evaluable`` is ``in_frame``)."""
    try:
        metadata = pq.read_schema(jobs).metadata or {}
        if metadata.get(MIN_VISIBLE_METADATA) == MIN_VISIBLE_OFF:
            return None
        min_visible = float(metadata.get(MIN_VISIBLE_METADATA, b"nan").decode())
    except (OSError, ValueError, pa.ArrowException):
        min_visible = float("nan")
    return min_visible if 0.0 <= min_visible <= 1.0 else DEFAULT_MIN_VISIBLE


def plan_protocol(jobs: Path, model: str) -> str:
    """What ``model`` sees in the plan at ``jobs`` (``Framing.protocol``'s line; "" for a plan from
    before plans recorded it, or another model's)."""
    try:
        raw = (pq.read_schema(jobs).metadata or {}).get(PROTOCOL_METADATA)
        line = json.loads(raw).get(model, "") if raw is not None else ""
    except (OSError, ValueError, AttributeError, pa.ArrowException):
        return ""
    return line if isinstance(line, str) else ""


def _ground_truth_sql(con: duckdb.DuckDBPyConnection, jobs: Path, truths: bool) -> str | None:
    """The ``ground_truth`` view: per job of the plan, its truth columns and ``evaluable``
    (None for a jobs table without the columns it needs: one written by hand, or very old)."""
    columns = _columns(con, "jobs")
    if not {"job", "in_frame"} <= columns.keys():
        return None
    if "truth_key" not in columns:  # planned without truth passes: the geometric flag alone
        model = "model, " if "model" in columns else ""
        return (f"CREATE VIEW ground_truth AS SELECT job, {model}NULL::VARCHAR AS truth_key, NULL::INTEGER AS gt_x0, "
                "NULL::INTEGER AS gt_y0, NULL::INTEGER AS gt_x1, NULL::INTEGER AS gt_y1, "
                "NULL::BIGINT AS visible_pixels, NULL::BIGINT AS silhouette_pixels, "
                "NULL::DOUBLE AS visible_fraction, in_frame AS evaluable FROM jobs")
    min_visible = plan_min_visible(jobs)
    source = ("(SELECT truth_key, gt_x0, gt_y0, gt_x1, gt_y1, visible_pixels, silhouette_pixels, visible_fraction "
              "FROM truths)") if truths else \
        ("(SELECT NULL::VARCHAR AS truth_key, NULL::INTEGER AS gt_x0, NULL::INTEGER AS gt_y0, "
         "NULL::INTEGER AS gt_x1, NULL::INTEGER AS gt_y1, NULL::BIGINT AS visible_pixels, "
         "NULL::BIGINT AS silhouette_pixels, NULL::DOUBLE AS visible_fraction WHERE false)")
    model = "j.model, " if "model" in columns else ""  # a spec with several models: a row per (job, model)
    evaluable = "j.in_frame" if min_visible is None else (  # no gate: the passes are a control's
        "CASE WHEN NOT j.in_frame THEN false WHEN t.truth_key IS NULL THEN NULL "
        f"ELSE coalesce(t.visible_fraction >= {min_visible!r}, false) END")
    return (f"CREATE VIEW ground_truth AS SELECT j.job, {model}j.truth_key, t.gt_x0, t.gt_y0, t.gt_x1, t.gt_y1, "
            f"t.visible_pixels, t.silhouette_pixels, t.visible_fraction, {evaluable} AS evaluable "
            f"FROM jobs j LEFT JOIN {source} t ON t.truth_key = j.truth_key")


def _has(con: duckdb.DuckDBPyConnection, name: str) -> bool:
    return bool(con.execute("SELECT count(*) FROM duckdb_views() WHERE view_name = ? AND NOT internal",
                            [name]).fetchone()[0])


def _columns(con: duckdb.DuckDBPyConnection, view: str) -> dict[str, str]:
    return {name: kind for name, kind, *_ in con.execute(f"DESCRIBE {identifier(view)}").fetchall()}
