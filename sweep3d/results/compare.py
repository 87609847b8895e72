"""Views that compare the models of one experiment on the same jobs (paired by ``job``).

Two models are compared on the jobs both answered validly and both may be judged on (``counted``
in ``results``: an unevaluable job is no evidence either way), so each difference is paired: the
same render (or the same scene seen at each model's own framing) judged by both. For each pair
of models (``model_a`` before ``model_b`` in spec order):

``model_accuracy``
    per model: n, n_correct, accuracy and its Wilson interval (counted results only).
``model_agreement``
    per pair: n (jobs both answered), accuracy of each, ``fixed`` (a wrong, b right),
    ``broken`` (a right, b wrong), the difference b − a, McNemar's exact p-value, the share of
    jobs with the same top-1 class (``same_top1``) and Cohen's kappa on correct/wrong.
``model_comparison``
    the same per control value (``parameter``, ``level``, ``label`` as in ``control_levels``):
    each model's accuracy with its Wilson interval, fixed, broken, difference and p-value.
``model_regions``
    single values and pairs of values (as in ``failure_modes``) with at least 10 paired jobs,
    ranked by p-value: ``p_holm`` is Holm's adjustment over every region of the pair, so a
    region is called ``better`` or ``worse`` only when it holds after looking at all of them.
``model_changes``
    the jobs on which two models disagree on correctness (``change`` = fixed or broken), with
    the scene, both top-1 classes and both image keys.

McNemar's test is exact (``mcnemar_p(b, c)``: two-sided binomial test of b fixed against c
broken at one half), so it holds for the few discordant jobs of a small grid too.
"""

from __future__ import annotations

import duckdb

from sweep3d.results.measures import NOT_A_MEASURE
from sweep3d.results.quoting import literal

#: Below this many paired jobs a region is not ranked (as ``failure_modes``'s default).
MIN_REGION = 10
ALPHA = 0.05

COMPARE_VIEWS = ("model_accuracy", "model_agreement", "model_comparison", "model_regions", "model_changes")
COMPARE_MACROS = ("mcnemar_p",)


def create_mcnemar(con: duckdb.DuckDBPyConnection) -> None:
    """``mcnemar_p(b, c)``: the exact two-sided McNemar p-value of b against c discordant pairs
    (1 when there are none), summed in log space so large counts neither overflow nor underflow."""
    con.execute(
        "CREATE OR REPLACE MACRO mcnemar_p(b, c) AS CASE WHEN coalesce(b, 0) + coalesce(c, 0) = 0 THEN 1.0 "
        "ELSE least(1.0, 2 * (SELECT sum(exp(lgamma(b + c + 1) - lgamma(k + 1) - lgamma(b + c - k + 1) "
        "- (b + c) * ln(2))) FROM range(0, least(b, c) + 1) t(k))) END"
    )


def register_compare_views(con: duckdb.DuckDBPyConnection, models: list[str], has_top1: bool) -> bool:
    """Create the comparison views over ``results_all`` (every model's results) for ``models`` in
    spec order; nothing when there are fewer than two. Needs ``control_levels``."""
    create_mcnemar(con)
    if len(models) < 2:
        return False
    ranks = ", ".join(f"({literal(m)}, {i})" for i, m in enumerate(models))
    top1 = "top1_label" if has_top1 else "NULL::VARCHAR"
    accuracy = ("n_correct_{s} / nullif(n, 0) AS accuracy_{s}, wilson_low(n_correct_{s}, n) AS wilson_low_{s}, "
                "wilson_high(n_correct_{s}, n) AS wilson_high_{s}")
    both = f"{accuracy.format(s='a')}, {accuracy.format(s='b')}"
    counts = ("count(*) AS n, count(*) FILTER (WHERE correct_a) AS n_correct_a, "
              "count(*) FILTER (WHERE correct_b) AS n_correct_b, "
              "count(*) FILTER (WHERE NOT correct_a AND correct_b) AS fixed, "
              "count(*) FILTER (WHERE correct_a AND NOT correct_b) AS broken")
    differ = "(fixed - broken) / nullif(n, 0) AS difference, mcnemar_p(fixed, broken) AS p_value"
    for sql in (
        f"""CREATE OR REPLACE VIEW model_ranks AS SELECT * FROM (VALUES {ranks}) t(model, model_rank)""",
        f"""CREATE OR REPLACE VIEW model_pairs AS
            WITH r AS (SELECT r.job, r.model, m.model_rank, r.correct, {top1} AS top1, r.image_key,
                              r.object, r.environment
                       FROM results_all r JOIN model_ranks m USING (model) WHERE r.counted)
            SELECT a.model AS model_a, b.model AS model_b, a.model_rank AS rank_a, b.model_rank AS rank_b,
                   a.job, a.object, a.environment, a.correct AS correct_a, b.correct AS correct_b,
                   a.top1 AS top1_a, b.top1 AS top1_b, a.image_key AS image_key_a, b.image_key AS image_key_b
            FROM r a JOIN r b ON a.job = b.job AND a.model_rank < b.model_rank""",
        """CREATE OR REPLACE VIEW model_accuracy AS
            SELECT *, n_correct / nullif(n, 0) AS accuracy, wilson_low(n_correct, n) AS wilson_low,
                   wilson_high(n_correct, n) AS wilson_high FROM (
                SELECT m.model, m.model_rank, count(r.job) FILTER (WHERE r.counted) AS n,
                       count(r.job) FILTER (WHERE r.counted AND r.correct) AS n_correct
                FROM model_ranks m LEFT JOIN results_all r USING (model) GROUP BY m.model, m.model_rank)
            ORDER BY model_rank""",
        f"""CREATE OR REPLACE VIEW model_agreement AS
            SELECT model_a, model_b, n, n_correct_a, n_correct_b, {both}, fixed, broken, {differ},
                   same_top1 / nullif(n, 0) AS same_top1,
                   (observed - expected) / nullif(1 - expected, 0) AS kappa
            FROM (SELECT *, (n - fixed - broken) / nullif(n, 0) AS observed,
                         (n_correct_a * n_correct_b + (n - n_correct_a) * (n - n_correct_b))
                             / nullif(n::DOUBLE * n, 0) AS expected
                  FROM (SELECT model_a, model_b, any_value(rank_a) AS rank_a, any_value(rank_b) AS rank_b, {counts},
                               count(*) FILTER (WHERE top1_a IS NOT DISTINCT FROM top1_b) AS same_top1
                        FROM model_pairs GROUP BY model_a, model_b))
            ORDER BY rank_a, rank_b""",
        f"""CREATE OR REPLACE VIEW model_comparison AS
            SELECT model_a, model_b, parameter, position, level, label, n, n_correct_a, n_correct_b, {both},
                   fixed, broken, {differ}
            FROM (SELECT p.model_a, p.model_b, any_value(p.rank_a) AS rank_a, any_value(p.rank_b) AS rank_b,
                         l.parameter, l.position, l.level, any_value(l.label) AS label, {counts}
                  FROM model_pairs p JOIN control_levels l USING (job) WHERE l.{NOT_A_MEASURE}
                  GROUP BY p.model_a, p.model_b, l.parameter, l.position, l.level)
            ORDER BY rank_a, rank_b, position, level""",
        f"""CREATE OR REPLACE VIEW model_regions AS
            WITH varied AS (SELECT l.* FROM control_levels l
                            SEMI JOIN control_parameters c ON c.parameter = l.parameter AND c.levels > 1
                            WHERE l.{NOT_A_MEASURE}),
            singles AS (
                SELECT p.model_a, p.model_b, l.parameter AS parameter_a, l.label AS label_a,
                       NULL::VARCHAR AS parameter_b, NULL::VARCHAR AS label_b, {counts}
                FROM model_pairs p JOIN varied l USING (job)
                GROUP BY p.model_a, p.model_b, l.parameter, l.label),
            doubles AS (
                SELECT p.model_a, p.model_b, a.parameter AS parameter_a, a.label AS label_a,
                       b.parameter AS parameter_b, b.label AS label_b, {counts}
                FROM model_pairs p JOIN varied a USING (job) JOIN varied b ON b.job = p.job AND a.position < b.position
                GROUP BY p.model_a, p.model_b, a.parameter, a.label, b.parameter, b.label),
            tested AS (
                SELECT *, {differ} FROM (SELECT * FROM singles UNION ALL SELECT * FROM doubles)
                WHERE n >= {MIN_REGION}),
            ranked AS (
                SELECT *, row_number() OVER w AS k, count(*) OVER (PARTITION BY model_a, model_b) AS m
                FROM tested WINDOW w AS (PARTITION BY model_a, model_b ORDER BY p_value, abs(difference) DESC,
                                                                        parameter_a, label_a, parameter_b, label_b))
            SELECT model_a, model_b, parameter_a, label_a, parameter_b, label_b, n, n_correct_a, n_correct_b,
                   {both}, fixed, broken, difference, p_value,
                   least(1.0, max((m - k + 1) * p_value) OVER (PARTITION BY model_a, model_b ORDER BY k
                                                               ROWS UNBOUNDED PRECEDING)) AS p_holm,
                   CASE WHEN least(1.0, max((m - k + 1) * p_value) OVER (PARTITION BY model_a, model_b ORDER BY k
                                                                         ROWS UNBOUNDED PRECEDING)) >= {ALPHA}
                        THEN 'same' WHEN difference > 0 THEN 'better' ELSE 'worse' END AS verdict
            FROM ranked ORDER BY model_a, model_b, k""",
        """CREATE OR REPLACE VIEW model_changes AS
            SELECT model_a, model_b, job, object, environment,
                   CASE WHEN correct_b THEN 'fixed' ELSE 'broken' END AS change,
                   top1_a, top1_b, image_key_a, image_key_b
            FROM model_pairs WHERE correct_a <> correct_b
            ORDER BY rank_a, rank_b, change DESC, job""",
    ):
        con.execute(sql)
    return True
