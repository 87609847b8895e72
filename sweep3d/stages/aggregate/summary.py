"""Summaries of a run's results, computed by DuckDB over the ``results`` view.

Accuracy counts only valid predictions (a render or model output with NaN/inf is excluded and
counted separately), so no non-finite value is ever averaged in silently.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import duckdb

MAX_LEVELS = 12  # a parameter with more distinct values is binned
BINS = 10


@dataclass
class ControlEffect:
    column: str
    levels: list[Any]  # value or bin centre
    labels: list[str]
    accuracy: list[float]
    count: list[int]


@dataclass
class Summary:
    jobs: int
    evaluated: int
    invalid: int
    correct: int
    accuracy: float | None
    objects: list[str]
    environments: list[str]
    scene_accuracy: list[list[float | None]]  # [object][environment]
    scene_count: list[list[int]]
    effects: list[ControlEffect] = field(default_factory=list)
    failures: list[dict[str, Any]] = field(default_factory=list)
    per_object: list[dict[str, Any]] = field(default_factory=list)


def summarise(con: duckdb.DuckDBPyConnection, columns: list[str], failure_limit: int = 48) -> Summary:
    """Summarise the ``results`` view of ``con`` (see :meth:`Store.connect`).

    Args:
        columns: the control-parameter columns of the jobs table.
    """
    jobs = con.execute("SELECT count(*) FROM jobs").fetchone()[0] if _has_view(con, "jobs") else 0
    if not _has_view(con, "results"):
        return Summary(jobs, 0, 0, 0, None, [], [], [], [])
    evaluated, invalid, correct = con.execute(
        "SELECT count(*), count(*) FILTER (WHERE NOT valid), count(*) FILTER (WHERE valid AND correct) FROM results"
    ).fetchone()
    valid = evaluated - invalid
    accuracy = correct / valid if valid else None

    objects = [r[0] for r in con.execute("SELECT DISTINCT object FROM jobs ORDER BY 1").fetchall()]
    environments = [r[0] for r in con.execute("SELECT DISTINCT environment FROM jobs ORDER BY 1").fetchall()]
    cells = {
        (o, e): (acc, n)
        for o, e, acc, n in con.execute(
            "SELECT object, environment, avg(correct::DOUBLE), count(*) FROM results WHERE valid GROUP BY 1, 2"
        ).fetchall()
    }
    scene_accuracy = [[cells.get((o, e), (None, 0))[0] for e in environments] for o in objects]
    scene_count = [[cells.get((o, e), (None, 0))[1] for e in environments] for o in objects]

    effects = [e for e in (_effect(con, c) for c in columns) if e is not None]
    failures = [
        dict(zip(["job", "object", "environment", "image_key", "top1_label", "topk_labels", "topk_probs", "loss"], r))
        for r in con.execute(
            "SELECT job, object, environment, image_key, top1_label, topk_labels, topk_probs, loss "
            "FROM results WHERE valid AND NOT correct ORDER BY loss DESC, job LIMIT ?", [failure_limit]
        ).fetchall()
    ]
    per_object = [
        dict(zip(["object", "accuracy", "count", "top_wrong"], r))
        for r in con.execute(
            "SELECT object, avg(correct::DOUBLE), count(*), "
            "mode(top1_label) FILTER (WHERE NOT correct) FROM results WHERE valid GROUP BY 1 ORDER BY 1"
        ).fetchall()
    ]
    return Summary(jobs, evaluated, invalid, correct, accuracy, objects, environments, scene_accuracy,
                   scene_count, effects, failures, per_object)


def _has_view(con: duckdb.DuckDBPyConnection, name: str) -> bool:
    return bool(con.execute(
        "SELECT count(*) FROM duckdb_views() WHERE view_name = ? AND NOT internal", [name]).fetchone()[0])


def _effect(con: duckdb.DuckDBPyConnection, column: str) -> ControlEffect | None:
    """Accuracy at each value of one control parameter (binned when it has many values)."""
    q = f'"{column}"'
    distinct, numeric = con.execute(
        f"SELECT count(DISTINCT {q}), bool_and(typeof({q}) IN ('DOUBLE','BIGINT','INTEGER','FLOAT')) "
        f"FROM results WHERE {q} IS NOT NULL"
    ).fetchone()
    if distinct is None or distinct < 2:
        return None
    if distinct <= MAX_LEVELS or not numeric:
        rows = con.execute(
            f"SELECT {q}, avg(correct::DOUBLE), count(*) FROM results WHERE valid AND {q} IS NOT NULL "
            f"GROUP BY 1 ORDER BY 1"
        ).fetchall()
        return ControlEffect(column, [r[0] for r in rows], [_fmt(r[0]) for r in rows],
                             [r[1] for r in rows], [r[2] for r in rows])
    lo, hi = con.execute(f"SELECT min({q}), max({q}) FROM results").fetchone()
    width = (hi - lo) / BINS
    rows = con.execute(
        f"SELECT least(floor(({q} - ?) / ?), ?)::INTEGER AS b, avg(correct::DOUBLE), count(*) "
        f"FROM results WHERE valid AND {q} IS NOT NULL GROUP BY 1 ORDER BY 1",
        [lo, width, BINS - 1],
    ).fetchall()
    centres = [lo + (b + 0.5) * width for b, _, _ in rows]
    labels = [f"{_fmt(lo + b * width)}–{_fmt(lo + (b + 1) * width)}" for b, _, _ in rows]
    return ControlEffect(column, centres, labels, [r[1] for r in rows], [r[2] for r in rows])


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


@dataclass(frozen=True)
class Region:
    """One control parameter's value (or bin) and how the model did there."""

    column: str
    label: str
    accuracy: float
    count: int


def weakest_regions(summary: Summary, min_count: int = 3, top: int = 3) -> list[Region]:
    """The parameter values with the lowest accuracy, each supported by ``min_count`` results."""
    regions = [Region(e.column, label, acc, n)
               for e in summary.effects for label, acc, n in zip(e.labels, e.accuracy, e.count)
               if n >= min_count and acc is not None]
    return sorted(regions, key=lambda r: (r.accuracy, -r.count))[:top]
