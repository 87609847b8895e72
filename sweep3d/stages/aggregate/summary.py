"""Summaries of a run's results, computed by DuckDB over the ``results`` view.

Accuracy counts only valid predictions (a render or model output with NaN/inf is excluded and
counted separately), so no non-finite value is ever averaged in silently.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import duckdb

from sweep3d.stages.aggregate.views import has_view, register_views


@dataclass
class ControlEffect:
    """Accuracy at each level (value or bin) of one parameter, with its 95 % Wilson interval."""

    column: str
    levels: list[int]  # level index in the ``control_levels`` view
    labels: list[str]
    accuracy: list[float | None]
    count: list[int]
    low: list[float | None]
    high: list[float | None]


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
    """Summarise the ``results`` view of ``con`` (see :func:`~sweep3d.stages.aggregate.connect`).

    Args:
        columns: the control-parameter columns of the jobs table.
    """
    jobs = con.execute("SELECT count(*) FROM jobs").fetchone()[0] if has_view(con, "jobs") else 0
    if not has_view(con, "results"):
        return Summary(jobs, 0, 0, 0, None, [], [], [], [])
    evaluated, invalid, correct = con.execute(
        "SELECT count(*), count(*) FILTER (WHERE NOT valid), count(*) FILTER (WHERE valid AND correct) FROM results"
    ).fetchone()
    if not has_view(con, "control_accuracy"):  # a connection made without aggregate.connect
        register_views(con)
    valid = evaluated - invalid
    accuracy = correct / valid if valid else None

    objects = [r[0] for r in con.execute("SELECT DISTINCT object FROM jobs ORDER BY 1").fetchall()]
    environments = [r[0] for r in con.execute("SELECT DISTINCT environment FROM jobs ORDER BY 1").fetchall()]
    cells = {
        (o, e): (acc, n)
        for o, e, acc, n in con.execute(
            "SELECT object, environment, accuracy, n FROM scene_accuracy WHERE n > 0"
        ).fetchall()
    }
    scene_accuracy = [[cells.get((o, e), (None, 0))[0] for e in environments] for o in objects]
    scene_count = [[cells.get((o, e), (None, 0))[1] for e in environments] for o in objects]

    effects = control_effects(con, columns)
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


def control_effects(con: duckdb.DuckDBPyConnection, columns: list[str]) -> list[ControlEffect]:
    """Accuracy per level of each of ``columns`` that takes two levels or more, in that order.

    Read from the ``control_accuracy`` view (levels and bins as defined there).
    """
    rows = con.execute(
        "SELECT parameter, level, label, accuracy, n, wilson_low, wilson_high FROM control_accuracy "
        "WHERE parameter IN (SELECT parameter FROM control_parameters WHERE levels > 1) "
        "AND list_contains(?, parameter) ORDER BY level", [columns]
    ).fetchall()
    effects = {c: ControlEffect(c, [], [], [], [], [], []) for c in columns}
    for column, level, label, accuracy, count, low, high in rows:
        effect = effects[column]
        for values, value in ((effect.levels, level), (effect.labels, label), (effect.accuracy, accuracy),
                              (effect.count, count), (effect.low, low), (effect.high, high)):
            values.append(value)
    return [e for e in effects.values() if e.levels]


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
