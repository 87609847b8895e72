"""Paired comparisons of two values of one parameter on the same configurations.

"Background A against B" is a paired question when both backgrounds were tried on the same
poses (a grid, or a spec with ``[policy] paired``): each pose then says which background the
model got right, and McNemar's exact test on the discordant pairs is far more sensitive than
comparing two accuracies. A pair is two counted results (``valid``, and ``evaluable`` not false
when the results have it) that differ in one parameter and agree on everything else:

- for a control parameter (``material_skin``, ``blur_sigma``, …): the same object and
  environment and the same value of every other parameter;
- for ``environment`` (``object``): the same object (environment) and the same value of every
  control parameter that applies in both scenes. A control limited to one of them (``environments
  = [...]``) is part of what differs, so it does not keep the scenes from pairing.

Pairs are one to one: where the same configuration occurs several times on a side (a control
that applies in one scene only varies it, or a policy drew it twice), its k-th occurrence (in
job order) pairs with the k-th on the other side, and the rest stay unpaired.

``paired_jobs``
    one row per pair: parameter, position, value_a, value_b (a before b: spec order for objects and
    environments, value order for controls), both jobs, objects, environments, correct and image keys.
``paired_values``
    per (parameter, value_a, value_b): n pairs, n_correct and accuracy of each side,
    ``a_right_b_wrong``, ``a_wrong_b_right``, difference (b − a), McNemar's exact p-value
    and ``p_holm``, Holm's adjustment over the value pairs of the same parameter.
``paired_environments``
    ``paired_values`` of the environments (environment_a, environment_b, ...).
"""

from __future__ import annotations

import duckdb

from sweep3d.results.compare import create_mcnemar
from sweep3d.results.quoting import identifier, literal

PAIRED_VIEWS = ("paired_jobs", "paired_values", "paired_environments")
SCENE = ("object", "environment")


def register_paired_views(con: duckdb.DuckDBPyConnection, parameters: list[tuple[str, bool]],
                          result_columns: set[str]) -> None:
    """Create the paired views over ``results`` for ``parameters`` (name, numeric), as
    ``control_columns`` lists them; nothing when the results have no scene columns."""
    if not set(SCENE) <= {name for name, _ in parameters}:
        return
    create_mcnemar(con)
    counted = "counted" if "counted" in result_columns else "valid AND evaluable IS NOT FALSE" if "evaluable" in result_columns else "valid"
    image = "image_key" if "image_key" in result_columns else "NULL::VARCHAR AS image_key"
    controls = [name for name, _ in parameters if name not in SCENE]
    ctes = [f"counted AS MATERIALIZED (SELECT job, object, environment, correct, {image}"
            f"{''.join(', ' + identifier(c) for c in controls)} FROM results WHERE {counted})"]
    flags = "".join(f", count({identifier(c)}) > 0 AS applies_{i}" for i, c in enumerate(controls))
    ctes.append(f"scenes AS (SELECT object, environment{flags} FROM counted GROUP BY object, environment)")
    branches = []
    for position, (name, numeric) in enumerate(parameters):
        cte, branch = (_scene_branch if name in SCENE else _control_branch)(name, position, numeric, controls)
        ctes += cte
        branches.append(branch)
    con.execute("CREATE OR REPLACE VIEW paired_jobs AS WITH " + ",\n".join(ctes) + "\n"
                + "\nUNION ALL ".join(branches))
    # one branch per parameter, so a filter on ``parameter`` computes only the branches it keeps
    each = "\nUNION ALL ".join(f"SELECT {literal(name)} AS parameter, * EXCLUDE (parameter) FROM ({_values_sql(name)})"
                               for name, _ in parameters)
    con.execute(f"CREATE OR REPLACE VIEW paired_values AS SELECT * EXCLUDE (rank_a, rank_b) FROM ({each}) "
                "ORDER BY position, rank_a, rank_b")
    con.execute("CREATE OR REPLACE VIEW paired_environments AS SELECT value_a AS environment_a, "
                "value_b AS environment_b, * EXCLUDE (parameter, position, value_a, value_b) "
                "FROM paired_values WHERE parameter = 'environment'")


def _values_sql(parameter: str) -> str:
    """Counts, McNemar's p and Holm's adjustment per pair of values of ``parameter``."""
    return f"""
        WITH counts AS (
            SELECT parameter, position, value_a, value_b, rank_a, rank_b, n, n_correct_a, n_correct_b,
                   n_correct_a / nullif(n, 0) AS accuracy_a, n_correct_b / nullif(n, 0) AS accuracy_b,
                   a_right_b_wrong, a_wrong_b_right, (n_correct_b - n_correct_a) / nullif(n, 0) AS difference,
                   mcnemar_p(a_right_b_wrong, a_wrong_b_right) AS p_value
            FROM (SELECT parameter, position, value_a, value_b, rank_a, rank_b, count(*) AS n,
                         count(*) FILTER (WHERE correct_a) AS n_correct_a,
                         count(*) FILTER (WHERE correct_b) AS n_correct_b,
                         count(*) FILTER (WHERE correct_a AND NOT correct_b) AS a_right_b_wrong,
                         count(*) FILTER (WHERE correct_b AND NOT correct_a) AS a_wrong_b_right
                  FROM paired_jobs WHERE parameter = {literal(parameter)}
                  GROUP BY parameter, position, value_a, value_b, rank_a, rank_b)),
        ranked AS (
            SELECT *, row_number() OVER (PARTITION BY parameter ORDER BY p_value, rank_a, rank_b) AS k,
                   count(*) OVER (PARTITION BY parameter) AS m
            FROM counts)
        SELECT parameter, position, value_a, value_b, n, n_correct_a, n_correct_b, accuracy_a, accuracy_b,
               a_right_b_wrong, a_wrong_b_right, difference, p_value,
               least(1.0, max((m - k + 1) * p_value) OVER (PARTITION BY parameter ORDER BY k
                                                           ROWS UNBOUNDED PRECEDING)) AS p_holm, rank_a, rank_b
        FROM ranked"""


def _scene_branch(name: str, position: int, numeric: bool, controls: list[str]) -> tuple[list[str], str]:
    """Pairs across scenes: ``name`` is object or environment, the other scene column is kept."""
    same = SCENE[1 - SCENE.index(name)]
    p = f"p{position}"
    keys = ", ".join(f"CASE WHEN s.applies_{i} THEN c.{identifier(col)} END AS k{i}" for i, col in enumerate(controls))
    ctes = [
        f"{p}_order AS (SELECT {name} AS value, rank() OVER (ORDER BY min(job)) AS rank FROM results GROUP BY {name})",
        f"""{p}_sides AS (SELECT c.job, c.object, c.environment, c.correct, c.image_key, c.{name} AS value,
                                 s.{name} AS other{', ' + keys if keys else ''}
                          FROM counted c JOIN scenes s ON s.{same} = c.{same} AND s.{name} <> c.{name})""",
        f"""{p}_ranked AS (SELECT *, row_number() OVER (PARTITION BY {same}, value, other
                                                         {''.join(f', k{i}' for i in range(len(controls)))}
                                                         ORDER BY job) AS occurrence FROM {p}_sides)""",
    ]
    match = "".join(f" AND a.k{i} IS NOT DISTINCT FROM b.k{i}" for i in range(len(controls)))
    branch = (f"SELECT {literal(name)} AS parameter, {position} AS position, {_pair_columns('a.value', 'b.value')} "
              f"FROM {p}_ranked a JOIN {p}_ranked b ON a.{same} = b.{same} AND a.other = b.value "
              f"AND b.other = a.value AND a.occurrence = b.occurrence{match} "
              f"JOIN {p}_order oa ON oa.value = a.value JOIN {p}_order ob ON ob.value = b.value "
              f"WHERE oa.rank < ob.rank")
    return ctes, branch


def _control_branch(name: str, position: int, numeric: bool, controls: list[str]) -> tuple[list[str], str]:
    """Pairs within a scene: two values of one control parameter, everything else equal."""
    p = f"p{position}"
    others = [c for c in controls if c != name]
    column = identifier(name)
    ctes = [
        f"""{p}_order AS (SELECT {column} AS value, dense_rank() OVER (ORDER BY {column}) AS rank
                          FROM counted WHERE {column} IS NOT NULL GROUP BY {column})""",
        f"""{p}_ranked AS (SELECT *, row_number() OVER (PARTITION BY object, environment
                                                         {''.join(', ' + identifier(c) for c in others)}, {column}
                                                         ORDER BY job) AS occurrence
                           FROM counted WHERE {column} IS NOT NULL)""",
    ]
    match = "".join(f" AND a.{identifier(c)} IS NOT DISTINCT FROM b.{identifier(c)}" for c in others)
    label = (lambda side: f"level_number_label(CAST({side}.{column} AS DOUBLE))") if numeric else (
        lambda side: f"CAST({side}.{column} AS VARCHAR)")
    branch = (f"SELECT {literal(name)} AS parameter, {position} AS position, {_pair_columns(label('a'), label('b'))} "
              f"FROM {p}_ranked a JOIN {p}_ranked b ON a.object = b.object AND a.environment = b.environment "
              f"AND a.occurrence = b.occurrence{match} "
              f"JOIN {p}_order oa ON oa.value = a.{column} JOIN {p}_order ob ON ob.value = b.{column} "
              f"WHERE oa.rank < ob.rank")
    return ctes, branch


def _pair_columns(value_a: str, value_b: str) -> str:
    return (f"CAST({value_a} AS VARCHAR) AS value_a, CAST({value_b} AS VARCHAR) AS value_b, "
            "oa.rank AS rank_a, ob.rank AS rank_b, a.job AS job_a, b.job AS job_b, "
            "a.object AS object_a, b.object AS object_b, a.environment AS environment_a, "
            "b.environment AS environment_b, a.correct AS correct_a, b.correct AS correct_b, "
            "a.image_key AS image_key_a, b.image_key AS image_key_b")
