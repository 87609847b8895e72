"""SQL views and macros over ``results``: the numbers behind every plot of the report.

:func:`connect` opens the store with them (:func:`register_views` adds them to a connection from
:meth:`Store.connect`), so the report reads the same numbers that ``sweep3d query`` sees.
Every *parameter* is a column of the jobs table that varies a scene: ``object``, ``environment``
and each control parameter ``<control id>_<param>`` (the plan lists them in the jobs file). A parameter's *levels* are its values, or, for a numeric parameter
with more than :data:`MAX_LEVELS` distinct values, :data:`BINS` equal-width bins; a job where a
control does not apply sits in the level ``(not applied)``. Accuracy counts the results that
``results.counted`` marks: valid predictions (NaN/inf outputs are counted apart, never averaged
in) of jobs not known to be unevaluable (out of frame, or too little of the object visible:
counted apart in ``not_evaluable``). Every ``n`` below counts those.

Views:

``control_parameters``
    parameter, position (spec order: object, environment, then controls), levels, numeric, binned.
``control_levels``
    one row per (result, parameter): job, object, environment, valid, counted, correct, parameter,
    position, level (0-based, in value order), label (text, for every kind of parameter), value
    (the level as a number: a numeric parameter's value, a bin's centre; NULL for text and where
    the control does not apply), absent.
``control_accuracy``
    per (parameter, level): label, value and absent as above, n (counted results), n_correct,
    accuracy, wilson_low, wilson_high. Besides the parameters, the results' *measures*
    (``measures.MEASURES``: ``visible_fraction``, ``margin``, ``iou``, those the results have) are
    levelled and binned the same way, after them, in ``control_values``, ``control_levels``,
    ``control_parameters`` and here; they are outcomes, not causes, so the views that compare
    values (``pair_accuracy``, ``variance_explained``, ``object_sensitivity``, ``failure_modes``,
    ``outcomes_by_value``, the model comparison) leave them out.
``pair_accuracy``
    the same per pair of levels of two parameters (both with 2 levels or more).
``scene_accuracy``
    the same per (object, environment).
``variance_explained``
    share of the variance of ``correct`` explained by each parameter (kind ``main``) and each
    pair beyond its two main effects (kind ``interaction``): eta² = between-group sum of
    squares / total sum of squares, and ``eta2_adjusted``, its part beyond chance (epsilon²,
    the ``epsilon_squared`` macro). In an unbalanced design the shares overlap.
``object_sensitivity``
    ``object_sensitivity(min_count := 10)`` with its default: per (object, other parameter),
    over the levels with at least ``min_count`` of the object's counted results (the others are
    left out, their results with them; a parameter left with fewer than two levels has no row):
    levels, n, worst and best level (the first in level order among equals) with their accuracy
    and count (``worst_n``, ``best_n``), accuracy range, eta² and ``eta2_adjusted`` within the
    object (the same ``epsilon_squared`` as ``variance_explained``); most sensitive first.
``object_confusions``
    per object, its wrong top-1 predictions with counts, share of its failures and rank (for a
    box or mask task, of its wrong-class failures only: a wrong box or a miss names the right class).
``part_visibility``
    only when the spec asks for it (a UV pass): per (object, part of its surface), accuracy
    over the results that show the part (see :mod:`sweep3d.results.part_views`).
``not_evaluable``, ``outcomes_by_value``, ``iou_by_object``
    jobs counted apart and why (a plan that knows which are in frame); for an evaluator with an
    ``outcome`` or ``iou`` role, outcomes per value and IoU per object (see
    :mod:`sweep3d.results.task_views`).
``average_precision``, ``average_precision_by_value``
    only for an evaluator with the detection roles (the built-in detector's ``det_scores`` and
    ``det_ious``): COCO's AP per object and its mean, overall and per level (see
    :mod:`sweep3d.results.detection`).

Which of these exist follows the experiment's evaluator (its roles, as the plan recorded them:
:mod:`sweep3d.results.base_views`), never the columns another experiment left in a shared
store.
``paired_jobs``, ``paired_values``, ``paired_environments``
    two values of one parameter on the same configurations (environment A against B on the
    same poses): the pairs, and per pair of values McNemar's exact test on the discordant ones
    (see :mod:`sweep3d.results.paired`).
``source_verdicts``, ``agreement``
    only when ``sweep3d realism score`` stored another source's verdicts (photographs, another
    renderer): the renders' verdicts beside the source's, and their agreement, PPV, NPV and
    Cohen's κ per source, model and object (see :mod:`sweep3d.results.agreement`).

Macros:

``wilson_low(k, n)``, ``wilson_high(k, n)``
    the 95 % Wilson score interval of a proportion k/n (NULL when n = 0): 0 <= low <= k/n <= high
    <= 1, low exactly 0 at k = 0 and high exactly 1 at k = n. The one definition of the interval:
    :func:`wilson_interval` reads it from here, and the report's script mirrors it.
``binomial_cdf(k, n, p)``
    P(X <= k) for X ~ Binomial(n, p), exact (summed in log space).
``epsilon_squared(ss_effect, df_effect, ss_error, df_error, ss_total)``
    an effect's share of the variance beyond chance: (SS_effect - df_effect * SS_error /
    df_error) / SS_total, at least 0.
``failure_modes(min_count := 10)``
    single levels and pairs of levels with at least ``min_count`` counted results and accuracy
    below the rest of their parameter, each with its difference from the rest (and interval), a
    one-sided exact test (McNemar's on a paired two-level parameter, else Fisher's), and the
    Benjamini–Hochberg ``q_value`` over every region tested; ``significant``:
    ``q_value`` < 0.05. See :mod:`sweep3d.results.failure_modes`.
``object_sensitivity(min_count := 10)``
    the ``object_sensitivity`` view at another minimum count per level.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Literal, Sequence

import duckdb
import pyarrow as pa
import pyarrow.parquet as pq

from sweep3d.cache import Store, lock_down
from sweep3d.core import Roles, UserError
from sweep3d.results.agreement import register_agreement_views, verdict_files
from sweep3d.results.base_views import plan_min_visible, register_results, results_roles
from sweep3d.results.compare import COMPARE_MACROS, COMPARE_VIEWS, register_compare_views
from sweep3d.results.counterfactuals import COUNTERFACTUALS, register_counterfactual_views
from sweep3d.results.detection import DETECTION_VIEWS, detection_views
from sweep3d.results.failure_modes import create_failure_modes
from sweep3d.results.findings import register_failure_grades_view, register_findings_view
from sweep3d.results.fragile import plan_drops_fragile, register_fragile
from sweep3d.results.measures import NOT_A_MEASURE
from sweep3d.results.paired import PAIRED_VIEWS, register_paired_views
from sweep3d.results.part_views import register_part_views
from sweep3d.results.quoting import identifier, literal
from sweep3d.results.task_views import TASK_VIEWS, register_task_views
from sweep3d.spec import JOB_COLUMNS, MODELS_METADATA, PARAMETERS_METADATA

MAX_LEVELS = 12  # a numeric parameter with more distinct values is binned

#: Default fewest counted results a failure mode's region, or a level in ``object_sensitivity``, needs.
MIN_COUNT = 10
BINS = 10
Z95 = 1.959963984540054  # two-sided 95 % normal quantile
NOT_APPLIED = "(not applied)"
SCENE_COLUMNS = ("object", "environment")
REQUIRED_COLUMNS = frozenset({"job", "object", "environment", "valid", "correct"})
#: ``counted`` for a ``results`` view made without it (by hand): see :data:`sweep3d.cache.store.COUNTED_SQL`.
_COUNTED = {True: "valid AND evaluable IS NOT FALSE", False: "valid"}
_NUMERIC = ("TINYINT", "SMALLINT", "INTEGER", "BIGINT", "HUGEINT", "UTINYINT", "USMALLINT", "UINTEGER",
            "UBIGINT", "FLOAT", "DOUBLE", "DECIMAL")

# accuracy and its Wilson interval from the counts n (counted results) and n_correct of an inner query
_ACCURACY = ("n_correct / nullif(n, 0) AS accuracy, wilson_low(n_correct, n) AS wilson_low, "
             "wilson_high(n_correct, n) AS wilson_high")

VIEWS = ("control_values", "control_stats", "control_levels", "control_parameters", "control_accuracy",
         "pair_accuracy", "scene_accuracy", "variance_explained", "object_sensitivity", "object_confusions",
         "part_visibility", *TASK_VIEWS, *DETECTION_VIEWS, *PAIRED_VIEWS, *COMPARE_VIEWS)
MACROS = ("wilson_low", "wilson_high", "binomial_cdf", "hypergeometric_cdf", "difference_low",
          "difference_high", "epsilon_squared", "failure_modes", "object_sensitivity",
          *COMPARE_MACROS)


def connect(store: Store, experiment: str | None = None, read_only: bool = False,
            writable: Sequence[Path] = (), model: str | None = None,
            views: Literal["all", "controls", "results"] = "all", read_once: bool = False) -> duckdb.DuckDBPyConnection:
    """:meth:`Store.connect` with the aggregate views and macros over ``experiment``'s results.

    An experiment may test several models: ``results_all`` then holds every model's results,
    ``results`` (and every view above it) one model's, and the ``model_*`` views compare them
    (see :mod:`sweep3d.results.compare`).

    Args:
        read_only: once the views exist, let the connection open only the files they read (and
            ``writable``) and change no setting (see :func:`~sweep3d.cache.store.lock_down`), for
            SQL that a user wrote.
        writable: files the caller itself will write through the connection (an export).
        model: the model ``results`` and the views show (its id); default the spec's first.
        views: ``"all"``; ``"results"`` to stop at ``results`` and the stability views beside it (the
            fragile verdicts); ``"controls"`` to stop after the per-control views (``control_accuracy``,
            ``control_stats``, ...), before the part, task, paired and failure-mode views. A follow-up
            reading its own jobs' verdicts need not wait for every view to be made (most of a cached
            ``grade``'s time).
        read_once: compute ``results`` once into a temp table before the views are made on it
            (:func:`materialise`), for a caller that reads most views (the summary, the report):
            each view's creation then binds that table instead of the segments' scans again (the
            cold quickstart's 33 views: 0.5 s → 0.2 s).

    Raises:
        UserError: when ``model`` is not one of the experiment's models.
    """
    files = store.view_files(experiment)
    con = store.connect(experiment, files)
    try:  # a view that cannot be made (a damaged file, a bad model name) leaves no connection open
        parameters, models, min_visible = None, [], None
        if "jobs" in files:
            register_results(con, files["jobs"][0], "truths" in files)
        if "jobs" in files:  # the experiment's jobs file, when it reads (one that does not is in store.unreadable)
            parameters = stored_parameters(store.jobs_path(experiment))
            models = stored_models(store.jobs_path(experiment))
            min_visible = plan_min_visible(store.jobs_path(experiment))
        shown = None
        if has_view(con, "results"):
            _create_macros(con)  # the stability views' Wilson intervals
            register_fragile(con, drop=experiment is not None and plan_drops_fragile(store.jobs_path(experiment)))
            shown = _select_model(con, models, model)
            if read_once:
                materialise(con, ["results"])
        elif model is not None:
            raise UserError(f"--model {model}: the experiment has no results yet")
        if views == "results":
            return con
        made = register_views(con, parameters, model=shown, min_visible=min_visible, controls_only=views == "controls")
        if views == "controls":
            return con
        if made and has_view(con, "results_all"):
            register_compare_views(con, models, results_roles(con).has("prediction"))
        verdicts = verdict_files(store)  # other sources' verdicts (photographs, another renderer)
        register_agreement_views(con, verdicts, experiment)
        explained = register_counterfactual_views(con, store, experiment,  # once `sweep3d explain` ran
                                                   files.get(COUNTERFACTUALS, []))
        register_findings_view(con, experiment)  # once `run` listed its findings
        register_failure_grades_view(con, experiment)
        if read_only:
            lock_down(con, [path for paths in files.values() for path in paths] + verdicts + explained, writable)
    except BaseException:
        con.close()
        raise
    return con


def stored_parameters(jobs_path: Path) -> list[str] | None:
    """The parameter columns a jobs file lists in its metadata (None if it lists none: older plans)."""
    try:
        metadata = pq.read_schema(jobs_path).metadata or {}
    except (OSError, ValueError, pa.ArrowException):
        return None
    listed = metadata.get(PARAMETERS_METADATA)
    return json.loads(listed) if listed is not None else None


def stored_models(jobs_path: Path) -> list[str]:
    """The models a jobs file's rows name, in spec order ([] for a plan from before specs named several)."""
    try:
        metadata = pq.read_schema(jobs_path).metadata or {}
    except (OSError, ValueError, pa.ArrowException):
        return []
    listed = metadata.get(MODELS_METADATA)
    return json.loads(listed) if listed is not None else []


def _select_model(con: duckdb.DuckDBPyConnection, models: list[str], model: str | None) -> str | None:
    """Keep every model's results as ``results_all`` and one model's as ``results``; returns the
    model ``results`` shows when the jobs table holds several (None: it holds one)."""
    if model is not None and model not in models:
        raise UserError(f"--model {model}: the experiment's models are {', '.join(models) or 'not recorded'}")
    con.execute("ALTER VIEW results RENAME TO results_all")
    chosen = model or (models[0] if models else None)
    where = f" WHERE model = {literal(chosen)}" if chosen is not None and len(models) > 1 else ""
    con.execute(f"CREATE VIEW results AS SELECT * FROM results_all{where}")
    return chosen if where else None


def register_views(con: duckdb.DuckDBPyConnection, parameters: list[str] | None = None, *,
                   model: str | None = None, min_visible: float | None = None, controls_only: bool = False) -> bool:
    """Create the aggregate views and macros on ``con`` (idempotent).

    Args:
        con: a connection whose ``jobs`` and ``results`` views exist (see :meth:`Store.connect`).
        parameters: the jobs table's control-parameter columns, as its plan listed them; None
            for a jobs table written before plans listed them (its parameters are then the
            columns that are neither keys nor bookkeeping).
        model: the model ``results`` shows, when the jobs table holds several (``not_evaluable``
            counts that model's jobs).
        min_visible: the plan's ``[evaluator] min_visible``, shown beside the jobs it excluded.
        controls_only: the per-control views only (no part, task, paired or failure-mode views).

    Returns:
        True if the views were created; False (and nothing created but the Wilson macros) when
        the connection has no ``results`` view yet, or one without the columns of
        :data:`REQUIRED_COLUMNS` (an evaluator that does not say what is correct).
    """
    _create_macros(con)
    if not has_view(con, "results"):
        return False
    result_columns = _columns(con, "results")
    if not REQUIRED_COLUMNS <= result_columns.keys():
        return False
    if "counted" not in result_columns:  # a results view made by hand, not by register_results
        con.execute("ALTER VIEW results RENAME TO results_uncounted")
        con.execute(f"CREATE VIEW results AS SELECT *, {_COUNTED['evaluable' in result_columns]} AS counted "
                    "FROM results_uncounted")
        result_columns = _columns(con, "results")
    columns = control_columns(con, parameters)
    roles = results_roles(con)
    for sql in _view_statements(columns, roles, result_measures(result_columns, roles)):
        con.execute(sql)
    if controls_only:
        return True
    register_part_views(con, set(result_columns))
    register_task_views(con, roles, set(result_columns), model, min_visible)
    detection_views(con, roles, set(result_columns))
    register_paired_views(con, columns, set(result_columns))
    create_failure_modes(con, MIN_COUNT, columns)
    return True


def control_columns(con: duckdb.DuckDBPyConnection, parameters: list[str] | None = None) -> list[tuple[str, bool]]:
    """The jobs table's parameter columns, each with whether it is numeric.

    ``object`` and ``environment`` come first; then the control parameters ``<control id>_<param>``:
    ``parameters`` as the plan listed them, or, for a jobs table from before plans listed them,
    every column that is neither a key nor bookkeeping.
    """
    columns = _columns(con, "jobs")
    out = [(name, False) for name in SCENE_COLUMNS if name in columns]
    if parameters is None:
        parameters = [name for name in columns if name not in JOB_COLUMNS and not name.endswith("_key")]
    out += [(name, _is_numeric(columns[name])) for name in parameters if name in columns]
    return out


# -- SQL --------------------------------------------------------------------------------------
def _create_macros(con: duckdb.DuckDBPyConnection) -> None:
    z2 = Z95 * Z95
    p = "(k::DOUBLE / n)"  # the bits of the views' accuracy, n_correct / n
    # The score interval's ends, clamped to [0, p] and [p, 1]: in floating point its low end at
    # k = 0 is a residue (6e-18 for 0 of 48, above the accuracy) and its high end at k = n can
    # fall a bit short of 1; clamped, they are exactly 0 and 1, and low <= p <= high always.
    for name, sign, clamp in (("wilson_low", "-", "least({p}, greatest(0.0, {end}))"),
                              ("wilson_high", "+", "greatest({p}, least(1.0, {end}))")):
        end = (f"(({p} + {z2!r} / (2 * n)) {sign} {Z95!r} * sqrt(greatest({p} * (1 - {p}) / n "
               f"+ {z2!r} / (4 * n::DOUBLE * n), 0))) / (1 + {z2!r} / n)")
        con.execute(f"CREATE OR REPLACE MACRO {name}(k, n) AS CASE WHEN n > 0 THEN {clamp.format(p=p, end=end)} END")
    # P(X <= k) for X ~ Binomial(n, p), summed exactly in log space (no overflow, no underflow
    # trouble: a term too small for a double is 0, as its share of the sum is).
    con.execute(
        "CREATE OR REPLACE MACRO binomial_cdf(k, n, p) AS CASE WHEN k >= n OR p <= 0 THEN 1.0 "
        "WHEN k < 0 OR p >= 1 THEN 0.0 ELSE least(1.0, (SELECT sum(exp(lgamma(n + 1) - lgamma(j + 1) "
        "- lgamma(n - j + 1) + j * ln(p) + (n - j) * ln(1 - p))) FROM range(0, k + 1) t(j))) END"
    )
    # Epsilon squared: eta² less the share that df_effect groups of pure noise would explain on
    # average (df_effect times the error mean square), never below 0. One formula for every
    # effect size that is "beyond chance" (variance_explained, object_sensitivity).
    con.execute(
        "CREATE OR REPLACE MACRO epsilon_squared(ss_effect, df_effect, ss_error, df_error, ss_total) AS "
        "greatest(ss_effect - df_effect * ss_error / nullif(df_error, 0), 0) / nullif(ss_total, 0)"
    )
    con.execute(
        "CREATE OR REPLACE MACRO level_number_label(x) AS CASE "
        "WHEN x = round(x) AND abs(x) < 1e9 THEN CAST(CAST(x AS BIGINT) AS VARCHAR) "
        "ELSE printf('%.4g', x) END"
    )


def wilson_interval(k: int, n: int) -> tuple[float, float]:
    """The 95 % Wilson interval of k successes in n (n > 0), from the same SQL macros the views use."""
    con = duckdb.connect()
    try:
        _create_macros(con)
        low, high = con.execute("SELECT wilson_low($k, $n), wilson_high($k, $n)", {"k": k, "n": n}).fetchone()
    finally:
        con.close()
    return float(low), float(high)


#: The views that do not depend on the experiment's parameters, in dependency order, after
#: ``control_values`` (built per experiment by :func:`_values_sql`).
_FIXED_VIEWS = (
        f"""CREATE OR REPLACE VIEW control_stats AS
            SELECT *, (hi - lo) / {BINS} AS width,
                   CASE WHEN binned THEN greatest(0, 1 - floor(log10((hi - lo) / {BINS})))::INTEGER END AS digits
            FROM (
                SELECT parameter, position, count(DISTINCT raw) AS distinct_values,
                       count(number) > 0 AND count(number) = count(raw) AS numeric,
                       min(number) AS lo, max(number) AS hi,
                       count(number) > 0 AND count(number) = count(raw) AND count(DISTINCT raw) > {MAX_LEVELS}
                           AND max(number) > min(number) AS binned
                FROM control_values GROUP BY parameter, position)""",
        # Each distinct level of a parameter is ranked and labelled once (a bin, a value, or not
        # applied: a few per parameter), then joined to the long-form rows: the same levels and
        # labels as ranking and labelling every (result, parameter) row, which cost several
        # times as much. A level is the rows that tie on the ranking's order (not applied, bin or
        # number, value): a bin, or a value's text, which fixes its number.
        f"""CREATE OR REPLACE VIEW control_levels AS
            WITH placed AS MATERIALIZED (
                SELECT job, object, environment, valid, counted, correct, parameter, position, raw IS NULL AS absent,
                       bin,
                       CASE WHEN bin IS NULL THEN raw END AS value, CASE WHEN bin IS NULL THEN number END AS number,
                       lo, width, digits
                FROM (SELECT v.*, s.lo, s.width, s.digits,
                             CASE WHEN s.binned AND v.number IS NOT NULL
                                  THEN least(floor((v.number - s.lo) / s.width), {BINS - 1})::INTEGER END AS bin
                      FROM control_values v JOIN control_stats s USING (parameter, position))),
            levels AS (
                SELECT parameter, absent, bin, value,
                       (dense_rank() OVER (PARTITION BY parameter ORDER BY absent, coalesce(bin::DOUBLE, number), value)
                        - 1)::INTEGER AS level,
                       CASE WHEN absent THEN '{NOT_APPLIED}'
                            WHEN bin IS NOT NULL THEN level_number_label(round(lo + bin * width, digits)) || '–'
                                                      || level_number_label(round(lo + (bin + 1) * width, digits))
                            WHEN number IS NOT NULL THEN level_number_label(number)
                            ELSE value END AS label,
                       CASE WHEN bin IS NOT NULL THEN lo + (bin + 0.5) * width ELSE number END AS level_value
                FROM (SELECT DISTINCT parameter, absent, bin, value, number, lo, width, digits FROM placed))
            SELECT p.job, p.object, p.environment, p.valid, p.counted, p.correct, p.parameter, p.position, l.level,
                   l.label, l.level_value AS value, p.absent
            FROM placed p JOIN levels l ON p.parameter = l.parameter AND p.absent = l.absent
                 AND p.bin IS NOT DISTINCT FROM l.bin AND p.value IS NOT DISTINCT FROM l.value""",
        """CREATE OR REPLACE VIEW control_parameters AS
            SELECT l.parameter, l.position, count(DISTINCT l.level)::INTEGER AS levels,
                   any_value(s.numeric) AS numeric, any_value(s.binned) AS binned
            FROM control_levels l JOIN control_stats s USING (parameter, position)
            GROUP BY l.parameter, l.position ORDER BY l.position""",
        f"""CREATE OR REPLACE VIEW control_accuracy AS
            SELECT *, {_ACCURACY} FROM (
                SELECT parameter, position, level, any_value(label) AS label, any_value(value) AS value,
                       bool_or(absent) AS absent,
                       count(*) FILTER (WHERE counted) AS n, count(*) FILTER (WHERE counted AND correct) AS n_correct
                FROM control_levels GROUP BY parameter, position, level)
            ORDER BY position, level""",
        f"""CREATE OR REPLACE VIEW pair_accuracy AS
            WITH varied AS (SELECT l.* FROM control_levels l
                            SEMI JOIN control_parameters p ON p.parameter = l.parameter AND p.levels > 1
                            WHERE l.{NOT_A_MEASURE})
            SELECT *, {_ACCURACY} FROM (
                SELECT a.parameter AS parameter_a, a.position AS position_a, a.level AS level_a,
                       any_value(a.label) AS label_a,
                       b.parameter AS parameter_b, b.position AS position_b, b.level AS level_b,
                       any_value(b.label) AS label_b,
                       count(*) FILTER (WHERE a.counted) AS n,
                       count(*) FILTER (WHERE a.counted AND a.correct) AS n_correct
                FROM varied a JOIN varied b ON a.job = b.job AND a.position < b.position
                GROUP BY a.parameter, a.position, a.level, b.parameter, b.position, b.level)
            ORDER BY position_a, position_b, level_a, level_b""",
        f"""CREATE OR REPLACE VIEW scene_accuracy AS
            SELECT *, {_ACCURACY} FROM (
                SELECT object, environment, count(*) FILTER (WHERE counted) AS n,
                       count(*) FILTER (WHERE counted AND correct) AS n_correct
                FROM results GROUP BY object, environment)
            ORDER BY object, environment""",
        f"""CREATE OR REPLACE VIEW variance_explained AS
            WITH overall AS (SELECT count(*) AS n, avg(correct::DOUBLE) AS p FROM results WHERE counted),
            total AS (SELECT n, n * p * (1 - p) AS ss FROM overall),
            main AS (
                SELECT c.parameter, c.position, sum(c.n * (c.accuracy - o.p) ^ 2) AS ss, count(*) - 1 AS df
                FROM control_accuracy c SEMI JOIN control_parameters v ON v.parameter = c.parameter AND v.levels > 1,
                     overall o
                WHERE c.n > 0 AND c.{NOT_A_MEASURE} GROUP BY c.parameter, c.position),
            cells AS (
                SELECT parameter_a, position_a, parameter_b, position_b, sum(c.n * (c.accuracy - o.p) ^ 2) AS ss,
                       count(*) - 1 AS df
                FROM pair_accuracy c, overall o WHERE c.n > 0
                GROUP BY parameter_a, position_a, parameter_b, position_b),
            effects AS (
                SELECT 'main' AS kind, m.parameter AS effect, m.parameter AS parameter_a,
                       NULL::VARCHAR AS parameter_b, m.ss AS sum_of_squares, m.df,
                       t.ss - m.ss AS ss_error, t.n - m.df - 1 AS df_error,
                       m.position AS position_a, NULL::INTEGER AS position_b
                FROM main m, total t
                UNION ALL
                SELECT 'interaction', c.parameter_a || ' × ' || c.parameter_b, c.parameter_a, c.parameter_b,
                       greatest(c.ss - a.ss - b.ss, 0), c.df - a.df - b.df, t.ss - c.ss, t.n - c.df - 1,
                       c.position_a, c.position_b
                FROM cells c JOIN main a ON a.parameter = c.parameter_a JOIN main b ON b.parameter = c.parameter_b,
                     total t)
            SELECT kind, effect, parameter_a, parameter_b, sum_of_squares, df,
                   sum_of_squares / nullif(t.ss, 0) AS eta2,
                   epsilon_squared(sum_of_squares, df, ss_error, df_error, t.ss) AS eta2_adjusted,
                   position_a, position_b
            FROM effects, total t
            ORDER BY eta2_adjusted DESC NULLS LAST, eta2 DESC, position_a, position_b NULLS FIRST""",
        # Level order fixes the order of the sum and which level a tie names, whatever order the
        # rows of control_levels come in. Levels with fewer than min_count results are left out,
        # their results with them: a 0 % of two images is no evidence of a sensitivity.
        f"""CREATE OR REPLACE MACRO object_sensitivity(min_count := {MIN_COUNT}) AS TABLE
            WITH per_level AS (
                SELECT object, parameter, position, level, any_value(label) AS label,
                       count(*) FILTER (WHERE counted) AS n, count(*) FILTER (WHERE counted AND correct) AS n_correct
                FROM control_levels WHERE parameter <> 'object' AND {NOT_A_MEASURE}
                GROUP BY object, parameter, position, level),
            kept AS (SELECT *, n_correct / n AS accuracy FROM per_level WHERE n >= greatest(min_count, 1)),
            pooled AS (SELECT object, parameter, sum(n) AS n, sum(n_correct) / sum(n) AS p
                       FROM kept GROUP BY object, parameter),
            effects AS (
                SELECT l.object, l.parameter, l.position, count(*)::INTEGER AS levels, any_value(o.n) AS n,
                       min(l.accuracy) AS accuracy_min, arg_min(l.label, l.accuracy ORDER BY l.level) AS worst_level,
                       arg_min(l.n, l.accuracy ORDER BY l.level) AS worst_n,
                       max(l.accuracy) AS accuracy_max, arg_max(l.label, l.accuracy ORDER BY l.level) AS best_level,
                       arg_max(l.n, l.accuracy ORDER BY l.level) AS best_n,
                       sum(l.n * (l.accuracy - o.p) ^ 2 ORDER BY l.level) AS ss,
                       any_value(o.n * o.p * (1 - o.p)) AS ss_total
                FROM kept l JOIN pooled o USING (object, parameter)
                GROUP BY l.object, l.parameter, l.position HAVING count(*) > 1)
            SELECT object, parameter, position, levels, n, accuracy_min, worst_level, worst_n, accuracy_max,
                   best_level, best_n, accuracy_max - accuracy_min AS accuracy_range, ss / nullif(ss_total, 0) AS eta2,
                   epsilon_squared(ss, levels - 1, ss_total - ss, n - levels, ss_total) AS eta2_adjusted
            FROM effects
            ORDER BY object, eta2_adjusted DESC NULLS LAST, eta2 DESC NULLS LAST, accuracy_range DESC, position""",
        "CREATE OR REPLACE VIEW object_sensitivity AS FROM object_sensitivity()",
)
# A box or mask task's failure with the right class (a wrong box, a miss) is no confusion.
_CONFUSIONS_VIEW = """CREATE OR REPLACE VIEW object_confusions AS
                SELECT object, top1_label AS prediction, count(*) AS n,
                       count(*) / sum(count(*)) OVER (PARTITION BY object) AS share,
                       row_number() OVER (PARTITION BY object ORDER BY count(*) DESC, top1_label) AS rank
                FROM results WHERE counted AND NOT correct{wrong_class} GROUP BY object, top1_label
                ORDER BY object, rank"""


def result_measures(result_columns: dict[str, str], roles: Roles) -> list[tuple[str, str]]:
    """(name, SQL over ``results``) of each measure of ``measures.MEASURES`` the results have (as
    numbers; ``result_columns``: name → DuckDB type): the object's visible fraction (truth passes),
    a classifier's ``margin`` (the best true class's probability less the best other's, from
    ``results.fragile``: one meaning of margin everywhere) and the IoU (an evaluator with the
    ``iou`` role)."""
    out = []
    if _is_numeric(result_columns.get("visible_fraction", "")):
        out.append(("visible_fraction", "visible_fraction"))
    if _is_numeric(result_columns.get("margin", "")):
        out.append(("margin", "margin"))
    if roles.has("iou") and _is_numeric(result_columns.get(roles.iou, "")):
        out.append(("iou", identifier(roles.iou)))
    return out


def _view_statements(parameters: list[tuple[str, bool]], roles: Roles,
                     measures: Sequence[tuple[str, str]] = ()) -> list[str]:
    """The CREATE statements, in dependency order (``object_confusions`` for an evaluator that
    names its predicted class)."""
    statements = ["CREATE OR REPLACE VIEW control_values AS " + _values_sql(parameters, measures), *_FIXED_VIEWS]
    if roles.has("prediction"):
        wrong_class = f" AND {identifier(roles.outcome)} = 'wrong_class'" if roles.has("outcome") else ""
        statements.append(_CONFUSIONS_VIEW.format(wrong_class=wrong_class))
    return statements


def _values_sql(parameters: list[tuple[str, bool]], measures: Sequence[tuple[str, str]] = ()) -> str:
    """``control_values``: results in long form, one row per (result, parameter), raw values.

    ``results`` (a join of the jobs with the deduplicated predictions) is computed once, into
    the columns read here, and each parameter's rows are read from that, not from a scan of
    ``results`` per parameter."""
    if not parameters:  # a jobs table without scene columns: an empty view of the right shape
        return ("SELECT NULL::BIGINT AS job, NULL::VARCHAR AS object, NULL::VARCHAR AS environment, "
                "NULL::BOOLEAN AS valid, NULL::BOOLEAN AS counted, NULL::BOOLEAN AS correct, "
                "NULL::VARCHAR AS parameter, NULL::INTEGER AS position, NULL::VARCHAR AS raw, NULL::DOUBLE AS number "
                "WHERE false")
    columns = list(dict.fromkeys(["job", "object", "environment", "valid", "counted", "correct",
                                  *(n for n, _ in parameters)]))
    parts = []
    for position, (name, numeric) in enumerate(parameters):
        column = identifier(name)
        number = f"CAST({column} AS DOUBLE)" if numeric else "NULL::DOUBLE"
        parts.append(
            f"SELECT job, object, environment, valid, counted, correct, {literal(name)} AS parameter, "
            f"{position} AS position, CAST({column} AS VARCHAR) AS raw, {number} AS number FROM read_once"
        )
    # a measure's rows, after the parameters' (NaN/inf as no value), only when some result has it
    for position, (name, _) in enumerate(measures, start=len(parameters)):
        column = identifier(name)
        parts.append(
            f"SELECT job, object, environment, valid, counted, correct, {literal(name)} AS parameter, "
            f"{position} AS position, CAST({column} AS VARCHAR) AS raw, {column} AS number FROM read_once "
            f"WHERE (SELECT count({column}) FROM read_once) > 0"
        )
    picked = [*map(identifier, columns), *(f"CASE WHEN isfinite(CAST({expr} AS DOUBLE)) THEN CAST({expr} AS DOUBLE) "
                                           f"END AS {identifier(name)}" for name, expr in measures)]
    return (f"WITH read_once AS MATERIALIZED (SELECT {', '.join(picked)} FROM results)\n"
            + "\nUNION ALL ".join(parts))


def materialise(con: duckdb.DuckDBPyConnection, views: Sequence[str]) -> None:
    """Compute each of ``views`` (in dependency order) once into a temp table, which the view
    then reads, for a caller that reads them several times (idempotent; a view the connection
    lacks is skipped).

    The rows are the view's own: a connection's views read a fixed set of immutable segments,
    so nothing goes stale. ``results`` alone is worth it for a few queries: each query over the
    view otherwise joins the jobs with the deduplicated predictions again.
    """
    for view in views:
        table = f"report_{view}"
        if not has_view(con, view) or _has_table(con, table):
            continue
        con.execute(f"CREATE TEMP TABLE {table} AS FROM {identifier(view)}")
        con.execute(f"CREATE OR REPLACE VIEW {identifier(view)} AS FROM {table}")


# -- helpers ----------------------------------------------------------------------------------
def no_results(store: Store, experiment: str, spec: str | Path) -> UserError:
    """The one line for a query or report that finds no results: the experiment never ran, or
    its first run is still going (a run records its jobs table, which ``results`` joins, once
    its stages are through)."""
    failed = last_run_failed(store, experiment)
    if failed:  # rerunning as it was would fail again: say what failed, not "run it"
        return UserError(f"no results for experiment {experiment!r} in {store.root}: {failed}; `sweep3d run` prints "
                         "each stage's first error: fix what it names, then run again")
    how = "run it first" if str(spec).startswith("<") else f"run: sweep3d run {spec}"  # <dict>: no file to name
    return UserError(f"no results for experiment {experiment!r} yet in {store.root}; {how} "
                     "(a run in progress shows its results when its stages finish)")


def last_run_failed(store: Store, experiment: str) -> str | None:
    """``every job of its last run (run 0dfd3a16fc5b, 2 jobs) failed: render 2`` when the
    experiment's latest recorded run failed somewhere, else None (never run, or nothing failed)."""
    stages = ("render", "postprocess", "infer")
    try:
        runs = store.table("runs")
    except (OSError, ValueError):  # an unreadable runs table: say no more than before
        return None
    if runs is None or "experiment" not in runs.column_names:
        return None
    mine = [row for row in runs.to_pylist() if row.get("experiment") == experiment and row.get("created_at")]
    if not mine:
        return None
    last = max(mine, key=lambda row: row["created_at"])
    failed = {stage: int(last.get(f"{stage}_failed") or 0) for stage in stages}
    if not any(failed.values()):
        return None
    counts = ", ".join(f"{stage} {n}" for stage, n in failed.items() if n)
    return f"every job of its last run (run {last.get('run_id')}, {last.get('jobs')} jobs) failed: {counts}"


def has_view(con: duckdb.DuckDBPyConnection, name: str) -> bool:
    """Whether ``con`` has a (user) view called ``name``."""
    return bool(con.execute(
        "SELECT count(*) FROM duckdb_views() WHERE view_name = ? AND NOT internal", [name]).fetchone()[0])


def _has_table(con: duckdb.DuckDBPyConnection, name: str) -> bool:
    return bool(con.execute("SELECT count(*) FROM duckdb_tables() WHERE table_name = ? AND temporary",
                            [name]).fetchone()[0])


def _columns(con: duckdb.DuckDBPyConnection, view: str) -> dict[str, str]:
    """Column name → DuckDB type name of ``view``, in order."""
    return {name: kind for name, kind, *_ in con.execute(f"DESCRIBE {identifier(view)}").fetchall()}


def _is_numeric(kind: str) -> bool:
    return kind.upper().split("(")[0] in _NUMERIC
