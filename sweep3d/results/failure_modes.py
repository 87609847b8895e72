"""Failure modes: the values (and pairs of values) where a model does worse than elsewhere.

A region is one level of a parameter (``occluder = half``), or a pair of levels of two
parameters. Each is compared with **the rest of its parameter**: the results at the
parameter's other levels (for a pair, the results that share one of its two values but not
both). Comparing a value with the overall accuracy instead, which includes the value itself,
dilutes the difference: with two levels, half of it. The test is one-sided (is the region
worse?):

- **McNemar's exact test** for a parameter with two levels seen on the same configurations
  (a paired design: every counted result at one level has its twin at the other, with the same
  object, environment and value of every other parameter): the discordant pairs decide;
- **Fisher's exact test** otherwise (the region's correct count against the hypergeometric
  law of the parameter's results).

The **family** is every region tested in the run: each value and each pair of values with
``min_count`` counted results or more, listed or not. ``q_value`` is the Benjamini–Hochberg
adjustment within it (the false discovery rate: among the regions called significant at
q < 0.05, about 5 % are expected to be chance; where no value matters at all, a simulation of
three crossed parameters named any region in about 3 % of seeds), and ``significant`` is
``q_value`` < 0.05.

``difference`` is the region's accuracy less the rest's, with Newcombe's hybrid score
interval (from the two Wilson intervals): the effect size, readable without the test. The
interval is neither adjusted for the regions tested nor paired, so it may exclude 0 where the
adjusted test does not call the region significant.

A level where a control does not apply (another scene) is no value of it: neither tested nor
part of any rest.

The earlier view's numbers stay available: ``p_overall`` (one-sided exact binomial test of the
region against the overall accuracy) and ``p_holm_overall`` (Holm's adjustment of those over
every region tested).
"""

from __future__ import annotations

import duckdb

from sweep3d.results.compare import ALPHA
from sweep3d.results.measures import NOT_A_MEASURE
from sweep3d.results.quoting import identifier, literal


def create_failure_modes(con: duckdb.DuckDBPyConnection, min_count: int, parameters: list[tuple[str, bool]]) -> None:
    """Create ``hypergeometric_cdf``, the ``difference_low``/``difference_high`` macros and
    ``failure_modes(min_count)`` on ``con``, which has the level views.

    Args:
        parameters: the results' parameter columns (name, numeric), object and environment first,
            as ``control_columns`` lists them.
    """
    _create_macros(con)
    con.execute(_failure_modes_sql(min_count, _twins_sql(parameters)))


def _twins_sql(parameters: list[tuple[str, bool]]) -> str:
    """One row per parameter whose counted results form twins: grouped by everything else (object,
    environment, every other parameter) and occurrence (the k-th result of a configuration at one
    value pairs with the k-th at the other, as ``paired_jobs`` pairs them), each group holds
    exactly one result at each of the same two values. The row has the two values as the levels label them (a before b) and the
    discordant pairs in both directions (a: the lower value, which is the parameter's first level).
    Results where the control does not apply are left out. One GROUP BY per parameter."""
    names = [name for name, _ in parameters]
    parts = []
    for name, _ in parameters:
        others = [identifier(other) for other in names if other != name]
        if not others:
            continue
        column = identifier(name)
        parts.append(f"""
            SELECT {literal(name)} AS parameter,
                   count(*) FILTER (WHERE right_lo AND NOT right_hi) AS a_right_b_wrong,
                   count(*) FILTER (WHERE right_hi AND NOT right_lo) AS a_wrong_b_right, count(*) AS n
            FROM (SELECT min({column}) AS lo, max({column}) AS hi, arg_min(correct, {column}) AS right_lo,
                         arg_max(correct, {column}) AS right_hi, count(*) AS k, count({column}) AS known
                  FROM (SELECT *, row_number() OVER (PARTITION BY {', '.join(others)}, {column} ORDER BY job)
                                      AS occurrence FROM results WHERE counted AND {column} IS NOT NULL)
                  GROUP BY {', '.join(others)}, occurrence)
            HAVING bool_and(k = 2 AND known = 2 AND lo <> hi) AND count(DISTINCT lo) = 1 AND count(DISTINCT hi) = 1""")
    if not parts:
        return ("SELECT NULL::VARCHAR AS parameter, NULL::BIGINT AS a_right_b_wrong, NULL::BIGINT AS a_wrong_b_right, "
                "NULL::BIGINT AS n WHERE false")
    return "\nUNION ALL ".join(parts)




def _create_macros(con: duckdb.DuckDBPyConnection) -> None:
    # P(X <= k), X ~ Hypergeometric(draws, successes, total): Fisher's one-sided p-value of a
    # region of ``draws`` results with k correct among ``total`` results with ``successes``
    # correct. Summed exactly in log space, as binomial_cdf is.
    con.execute(
        "CREATE OR REPLACE MACRO hypergeometric_cdf(k, draws, successes, total) AS "
        "CASE WHEN k >= least(draws, successes) THEN 1.0 "
        "WHEN k < greatest(0, draws - (total - successes)) THEN 0.0 "
        "ELSE least(1.0, (SELECT sum(exp(lgamma(successes + 1) - lgamma(j + 1) - lgamma(successes - j + 1) "
        "+ lgamma(total - successes + 1) - lgamma(draws - j + 1) - lgamma(total - successes - draws + j + 1) "
        "- lgamma(total + 1) + lgamma(draws + 1) + lgamma(total - draws + 1))) "
        "FROM range(greatest(0, draws - (total - successes))::BIGINT, (k + 1)::BIGINT) t(j))) END"
    )
    # Newcombe's hybrid score interval of k1/n1 - k2/n2 (his method 10), from Wilson intervals.
    for name, sign, own, other in (("difference_low", "-", "wilson_low", "wilson_high"),
                                   ("difference_high", "+", "wilson_high", "wilson_low")):
        con.execute(
            f"CREATE OR REPLACE MACRO {name}(k1, n1, k2, n2) AS CASE WHEN n1 > 0 AND n2 > 0 THEN "
            f"k1 / n1 - k2 / n2 {sign} sqrt((k1 / n1 - {own}(k1, n1)) ^ 2 + ({other}(k2, n2) - k2 / n2) ^ 2) END"
        )


def _failure_modes_sql(min_count: int, twins_sql: str) -> str:
    """The macro; ``twins_sql`` lists the parameters whose results are twins (:func:`_twins_sql`)."""
    twins = f"""SELECT v.parameter, v.a_right_b_wrong, v.a_wrong_b_right
                FROM ({twins_sql}) v
                JOIN totals t ON t.parameter = v.parameter AND t.levels = 2 AND t.n = 2 * v.n"""
    # A level where the control does not apply (``absent``: another scene) is no value of it: it
    # is neither tested nor part of any rest, which would mix scenes into the comparison.
    return f"""CREATE OR REPLACE MACRO failure_modes(min_count := {min_count}) AS TABLE
        WITH overall AS (SELECT avg(correct::DOUBLE) AS p FROM results WHERE counted),
        applied AS MATERIALIZED (FROM control_accuracy WHERE NOT absent AND {NOT_A_MEASURE}),
        totals AS MATERIALIZED (
            SELECT parameter, count(*) AS levels, min(level) AS first_level, sum(n)::BIGINT AS n,
                   sum(n_correct)::BIGINT AS n_correct
            FROM applied GROUP BY parameter HAVING count(*) > 1),
        twins AS ({twins}),
        pairs AS (
            SELECT p.*, least(a.accuracy, b.accuracy) AS accuracy_alone,
                   sum(p.n) OVER (PARTITION BY p.parameter_a, p.level_a, p.parameter_b)
                   + sum(p.n) OVER (PARTITION BY p.parameter_a, p.parameter_b, p.level_b) - 2 * p.n AS n_rest,
                   sum(p.n_correct) OVER (PARTITION BY p.parameter_a, p.level_a, p.parameter_b)
                   + sum(p.n_correct) OVER (PARTITION BY p.parameter_a, p.parameter_b, p.level_b) - 2 * p.n_correct
                       AS n_correct_rest
            FROM pair_accuracy p
            JOIN applied a ON a.parameter = p.parameter_a AND a.level = p.level_a
            JOIN applied b ON b.parameter = p.parameter_b AND b.level = p.level_b
            SEMI JOIN totals ta ON ta.parameter = p.parameter_a
            SEMI JOIN totals tb ON tb.parameter = p.parameter_b),
        regions AS (
            SELECT 1 AS size, c.parameter || ' = ' || c.label AS region,
                   c.parameter AS parameter_a, c.level AS level_a, c.label AS label_a,
                   NULL::VARCHAR AS parameter_b, NULL::INTEGER AS level_b, NULL::VARCHAR AS label_b,
                   c.n, c.n_correct, c.accuracy, c.wilson_low, c.wilson_high,
                   t.n - c.n AS n_rest, t.n_correct - c.n_correct AS n_correct_rest,
                   -- the twins' first value is the parameter's first level: orient by level, not label
                   CASE WHEN c.level = t.first_level THEN w.a_wrong_b_right ELSE w.a_right_b_wrong END AS worse_pairs,
                   CASE WHEN c.level = t.first_level THEN w.a_right_b_wrong ELSE w.a_wrong_b_right END AS better_pairs,
                   c.position AS position_a, NULL::INTEGER AS position_b, true AS listed
            FROM applied c JOIN totals t USING (parameter)
            LEFT JOIN twins w ON w.parameter = c.parameter
            UNION ALL
            SELECT 2, parameter_a || ' = ' || label_a || ' · ' || parameter_b || ' = ' || label_b,
                   parameter_a, level_a, label_a, parameter_b, level_b, label_b,
                   n, n_correct, accuracy, wilson_low, wilson_high, n_rest, n_correct_rest, NULL, NULL,
                   position_a, position_b, wilson_high < accuracy_alone
            FROM pairs),
        tested AS (
            SELECT r.*, r.n_correct_rest / nullif(r.n_rest, 0) AS accuracy_rest,
                   r.accuracy < r.n_correct_rest / r.n_rest AS below,
                   CASE WHEN r.worse_pairs IS NOT NULL THEN 'mcnemar' ELSE 'fisher' END AS test,
                   CASE WHEN r.accuracy >= r.n_correct_rest / r.n_rest THEN 1.0
                        WHEN r.worse_pairs IS NOT NULL
                        THEN binomial_cdf(r.better_pairs, r.worse_pairs + r.better_pairs, 0.5)
                        ELSE hypergeometric_cdf(r.n_correct, r.n, r.n_correct + r.n_correct_rest, r.n + r.n_rest)
                   END AS p_value,
                   CASE WHEN r.accuracy < o.p THEN binomial_cdf(r.n_correct, r.n, o.p) ELSE 1.0 END AS p_overall
            FROM regions r, overall o WHERE r.n >= greatest(min_count, 1) AND r.n_rest > 0),
        ranked AS (
            SELECT *, row_number() OVER (ORDER BY p_value, size, position_a, level_a, position_b, level_b) AS k,
                      count(*) OVER () AS m,
                      row_number() OVER (ORDER BY p_overall, size, position_a, level_a, position_b, level_b) AS k_all,
                      count(*) OVER () AS m_all
            FROM tested),
        adjusted AS (
            SELECT *, least(1.0, min(m * p_value / k) OVER (ORDER BY k DESC ROWS UNBOUNDED PRECEDING)) AS q_value,
                   least(1.0, max((m_all - k_all + 1) * p_overall) OVER (ORDER BY k_all ROWS UNBOUNDED PRECEDING))
                       AS p_holm_overall
            FROM ranked)
        SELECT size, region,
               parameter_a, level_a, label_a, parameter_b, level_b, label_b, n, n_correct, accuracy,
               wilson_low, wilson_high, n_rest, n_correct_rest, accuracy_rest, accuracy - accuracy_rest AS difference,
               difference_low(n_correct, n, n_correct_rest, n_rest) AS difference_low,
               difference_high(n_correct, n, n_correct_rest, n_rest) AS difference_high,
               test, p_value, q_value, q_value < {ALPHA} AS significant, p_overall, p_holm_overall,
               position_a, position_b
        FROM adjusted
        WHERE listed AND below
        ORDER BY difference_high, difference, n DESC, size, position_a, level_a, position_b, level_b"""
