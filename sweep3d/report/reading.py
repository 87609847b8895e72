"""The experiment's results as the report reads them, with work bounded by levels, not results.

Two things make a report of 10^6 results cheap to build:

- :func:`materialise_views` computes once the aggregate views the report reads many times
  (``results``, ``control_stats``, ``control_levels``, ``control_parameters``,
  ``control_accuracy``, ``pair_accuracy``, ``not_evaluable``) into temp tables that those views then read. The
  SQL and the rows are the views' own (a connection's views read a fixed set of immutable
  segments, so nothing goes stale); without it each of the report's queries recomputes their
  ranks and self-joins (at 10^6 results, minutes per query).
- :class:`Results` keeps one row per result (job, outcome, loss, top-1 prediction, image key
  and its *level* of each parameter, from ``control_levels``) in a temp table and answers what
  the panels ask: a region's examples, the joint counts the explorer aggregates, the images to
  embed. Nothing here holds a Python object per result.

Examples come wrong first (worst first: highest loss, or for a box or mask task without a loss,
lowest IoU with misses first), then correct, then invalid, then those of jobs
that are not evaluable (out of frame or hidden: never counted as right or wrong), so the first
rows of any slice are its most telling failures.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import duckdb

from sweep3d.core import Roles
from sweep3d.results import SCENE_COLUMNS, has_view, materialise, results_roles

WRONG, CORRECT, INVALID, NOT_EVALUABLE = 0, 1, 2, 3  # outcome codes; the first two are counted
OUTCOME_NAMES = ("wrong", "correct", "invalid", "not-evaluable")
TABLE = "report_levels"  # the temp table of one row per result
#: Views read many times by one report, in dependency order.
MATERIALISED = ("results", "control_stats", "control_levels", "control_parameters", "control_accuracy",
                "pair_accuracy", "not_evaluable")
#: The order examples come in: most telling first.
EXAMPLE_ORDER = "outcome, loss DESC NULLS LAST, job"


@dataclass(frozen=True)
class Parameter:
    """One scene parameter (``object``, ``environment`` or ``<control id>_<param>``) and its levels."""

    name: str
    labels: list[str]  # label of each level, by level index
    numeric: bool
    binned: bool

    @property
    def varies(self) -> bool:
        return len(self.labels) > 1


@dataclass(frozen=True)
class ResultRow:
    """One result as a gallery shows it."""

    job: int
    outcome: int  # WRONG, CORRECT or INVALID
    prediction: str | None
    image_key: str
    levels: tuple[int, ...]  # its level of each of :attr:`Results.parameters` (-1: none)
    why: str | None = None  # how a box or mask task's failure failed: "wrong box · IoU 0.32", "missed"


def materialise_views(con: duckdb.DuckDBPyConnection) -> None:
    """Compute the views of :data:`MATERIALISED` once; they then read the stored rows (idempotent)."""
    materialise(con, MATERIALISED)


class Results:
    """Every result with its level of each parameter, kept by DuckDB (see the module's doc).

    Args:
        con: a connection from ``results.connect`` (with the aggregate views).
        names: parameter names in the order wanted, e.g. ``object``, ``environment``, then the
            spec's control columns (names with no levels are skipped).
    """

    def __init__(self, con: duckdb.DuckDBPyConnection, names: Sequence[str], measures: Sequence[str] = ()) -> None:
        self.con = con
        self.parameters = read_parameters(con, names)
        #: the measures of ``measures`` the results have (visible fraction, margin, IoU): axes of the
        #: explorer only; their levels follow the parameters' (index ``len(parameters) + i``)
        self.measures = read_parameters(con, measures)
        columns = {row[0] for row in con.execute("DESCRIBE results").fetchall()}
        roles = results_roles(con)
        con.execute(_table_sql(columns, roles, [p.name for p in self.parameters + self.measures]))
        #: ORDER BY putting rows of ``results`` in example order (for SQL shown to the user).
        badness = badness_sql(roles)
        self.example_order_sql = ("ORDER BY NOT counted, correct" + (f", {badness} DESC" if badness != "NULL" else "")
                                  + ", job")

    def __len__(self) -> int:
        return int(self.con.execute(f"SELECT count(*) FROM {TABLE}").fetchone()[0])

    def index(self, name: str) -> int:
        """The position of parameter ``name`` in :attr:`parameters`."""
        return next(i for i, p in enumerate(self.parameters) if p.name == name)

    def examples(self, where: Mapping[str, int], limit: int, outcome: int = WRONG,
                 prediction: str | None = None) -> list[ResultRow]:
        """Up to ``limit`` results with ``outcome`` at the given level of each named parameter
        (and top-1 ``prediction`` if given), highest loss first."""
        terms = [f"{_level(self.index(name))} = ?" for name in where] + ["outcome = ?"]
        values: list[Any] = [*where.values(), outcome]
        if prediction is not None:
            terms.append("prediction = ?")
            values.append(prediction)
        return self._rows(" AND ".join(terms), values, limit)

    def rows(self, jobs: Sequence[int]) -> list[ResultRow]:
        """The results of ``jobs``, most telling first."""
        return self._rows("list_contains(?, job)", [list(jobs)], None)

    def cells(self, parameters: Sequence[int]) -> int:
        """How many combinations of levels of ``parameters`` hold at least one result."""
        columns = ", ".join(_level(p) for p in parameters) or "NULL"
        return int(self.con.execute(f"SELECT count(*) FROM (SELECT DISTINCT {columns} FROM {TABLE})").fetchone()[0])

    def counts(self, parameters: Sequence[int]) -> dict[str, list]:
        """The non-empty cells of the contingency table over ``parameters``, column by column.

        Returns:
            ``level`` (one list per parameter: each cell's level), ``n`` (counted results),
            ``k`` (correct ones) and ``total`` (with the invalid and unevaluable ones), cells in
            level order.
        """
        columns = [_level(p) for p in parameters]
        keys = ", ".join(columns)
        found = self.con.execute(
            f"SELECT {keys + ', ' if keys else ''}count(*) FILTER (WHERE outcome <= {CORRECT}) AS n, "
            f"count(*) FILTER (WHERE outcome = {CORRECT}) AS k, count(*) AS total FROM {TABLE}"
            + (f" GROUP BY {keys} ORDER BY {keys}" if keys else "")
        ).fetchnumpy()
        return {"level": [found[c].tolist() for c in columns],
                **{name: found[name].tolist() for name in ("n", "k", "total")}}

    def sample(self, cells: Sequence[Sequence[int]], first: Sequence[int], first_count: int,
               limit: int) -> list[int]:
        """Jobs whose images to embed: a few from every cell, failures first.

        Args:
            cells: groups of parameters, each defining cells (the joint table's, or each pair's).
                Results are taken round by round: the most telling result of every cell, then
                the second, … (within a round, wrong before right, highest loss first).
            first: parameters of the first view (its axes); its cells get ``first_count``
                results each before any round.
            limit: the most jobs returned.
        """
        ranks = [_rank(group) for group in cells] or ["1"]
        in_cell = f"least({', '.join(ranks)})" if len(ranks) > 1 else ranks[0]
        found = self.con.execute(
            f"SELECT job FROM (SELECT job, outcome, loss, {in_cell} AS in_cell, {_rank(first)} AS in_view "
            f"FROM {TABLE}) ORDER BY in_view > ?, in_cell, {EXAMPLE_ORDER} LIMIT ?", [first_count, limit]
        ).fetchnumpy()
        return found["job"].tolist()

    def describe(self, row: ResultRow) -> str:
        """``job 3 · object = mug · …`` for a gallery tile's title: the scene, and the control
        parameters that vary (one with a single value is stated once, in the page's header)."""
        values = [f"{p.name} = {p.labels[level]}" for p, level in zip(self.parameters, row.levels)
                  if level >= 0 and (p.varies or p.name in SCENE_COLUMNS)]
        return " · ".join([f"job {row.job}", *values])

    def fixed(self) -> list[tuple[str, str]]:
        """(name, value) of each parameter with a single value in the experiment."""
        return [(p.name, p.labels[0]) for p in self.parameters if not p.varies]

    def _rows(self, where: str, values: list[Any], limit: int | None) -> list[ResultRow]:
        levels = "".join(f", {_level(p)}" for p in range(len(self.parameters) + len(self.measures)))
        found = self.con.execute(
            f"SELECT job, outcome, prediction, image_key, why{levels} FROM {TABLE} WHERE {where} "
            f"ORDER BY {EXAMPLE_ORDER}" + (f" LIMIT {int(limit)}" if limit is not None else ""), values
        ).fetchall()
        return [ResultRow(int(job), int(outcome), prediction, str(key), tuple(int(v) for v in rest), why)
                for job, outcome, prediction, key, why, *rest in found]


def read_parameters(con: duckdb.DuckDBPyConnection, names: Sequence[str]) -> list[Parameter]:
    """The parameters of ``names`` that have levels, in that order, with their level labels."""
    known = {row[0]: row[1:] for row in con.execute(
        "SELECT parameter, numeric, binned FROM control_parameters").fetchall()}
    order = [name for name in names if name in known]
    labels: dict[str, list[str]] = {name: [] for name in order}
    for name, label in con.execute(
            "SELECT parameter, label FROM control_accuracy WHERE list_contains(?, parameter) ORDER BY level",
            [order]).fetchall():
        labels[name].append(label)
    return [Parameter(name, labels[name], bool(known[name][0]), bool(known[name][1])) for name in order]


def _table_sql(columns: set[str], roles: Roles, names: list[str]) -> str:
    """The CREATE statement of :data:`TABLE` (``columns``: those of ``results``; ``roles``: its
    evaluator's): results joined with their levels, one column per parameter."""
    prediction = "r.top1_label" if roles.has("prediction") else "NULL::VARCHAR"
    unevaluable = "r.evaluable IS FALSE" if "evaluable" in columns else "false"
    select = (f"SELECT r.job, (CASE WHEN r.counted THEN (CASE WHEN r.correct THEN {CORRECT} ELSE {WRONG} END) "
              f"WHEN {unevaluable} THEN {NOT_EVALUABLE} ELSE {INVALID} END)"
              f"::TINYINT AS outcome, {badness_sql(roles, 'r.')}::DOUBLE AS loss, {prediction} AS prediction, "
              f"r.image_key, {_why(roles)} AS why")
    if not names:
        return f"CREATE OR REPLACE TEMP TABLE {TABLE} AS {select} FROM results r"
    pivot = ", ".join(f"max(level) FILTER (WHERE parameter = {_literal(n)}) AS {_level(i)}" for i, n in enumerate(names))
    levels = "".join(f", coalesce(l.{_level(i)}, -1)::INTEGER AS {_level(i)}" for i in range(len(names)))
    return (f"CREATE OR REPLACE TEMP TABLE {TABLE} AS {select}{levels} FROM results r LEFT JOIN "
            f"(SELECT job, {pivot} FROM control_levels WHERE list_contains({_list(names)}, parameter) GROUP BY job) l "
            "USING (job)")


def badness_sql(roles: Roles, prefix: str = "") -> str:
    """How bad a result is, for ordering examples worst first: the loss, else (a box or mask task
    without one) 1 - IoU with a miss as IoU 0, else nothing."""
    if roles.has("loss"):
        return f"{prefix}{roles.loss}"
    if roles.has("iou"):
        return f"1 - coalesce({prefix}{roles.iou}, 0)"
    return "NULL"


def _why(roles: Roles) -> str:
    """SQL of a failure's reason for a box or mask task (``wrong box · IoU 0.32``; NULL when
    correct, or for classification, whose caption's predicted class says it)."""
    if not roles.has("outcome"):
        return "NULL::VARCHAR"
    reason = f"replace(r.{roles.outcome}, '_', ' ')"
    if roles.has("iou"):
        reason += f" || coalesce(printf(' · IoU %.2f', r.{roles.iou}), '')"
    return f"CASE WHEN r.counted AND NOT r.correct THEN {reason} END"


def _rank(parameters: Sequence[int]) -> str:
    """Each result's rank in its cell of ``parameters``, most telling first."""
    partition = ", ".join(_level(p) for p in parameters)
    return f"row_number() OVER ({'PARTITION BY ' + partition + ' ' if partition else ''}ORDER BY {EXAMPLE_ORDER})"


def _level(index: int) -> str:
    return f"l{index}"


def _literal(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"


def _list(texts: list[str]) -> str:
    return "[" + ", ".join(_literal(t) for t in texts) + "]"


def read_grades(con: duckdb.DuckDBPyConnection, model: str) -> dict[str, dict[str, Any]]:
    """Each finding's row of the ``findings`` view for ``model``, by its key (``{}`` before any
    listing: a store written before findings were graded, or one ``run`` did not list)."""
    if not has_view(con, "findings"):
        return {}
    cursor = con.execute("SELECT * FROM findings WHERE model = ? ORDER BY rank", [model])
    names = [d[0] for d in cursor.description]
    return {row["finding"]: row for row in (dict(zip(names, r)) for r in cursor.fetchall())}


def level_values(con: duckdb.DuckDBPyConnection) -> dict[str, list[tuple[int, str, float | None]]]:
    """Each parameter's levels as (level, label, value): a bin's middle, a number's value, None for
    a name (as ``control_accuracy`` has them); for placing a finding's region on the explorer's levels."""
    out: dict[str, list[tuple[int, str, float | None]]] = {}
    for name, level, label, value in con.execute(
            "SELECT parameter, level, label, value FROM control_accuracy ORDER BY position, level").fetchall():
        out.setdefault(name, []).append((int(level), str(label), None if value is None else float(value)))
    return out
