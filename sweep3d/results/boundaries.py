"""Failure boundaries: where along a numeric control the model starts to fail.

For each control parameter that the spec gives a range or a list of numbers, overall, per
object and per environment (where there are several and each has enough results), a step is
fitted to the counted results against the value (:mod:`sweep3d.stages.plan.step_fit`): the
accuracy ``accuracy_below`` up to the boundary and ``accuracy_above`` beyond it. The boundary is
where the fitted accuracy crosses ``level``, halfway between the two (a step crosses every level
between its plateaus at the same place), with its 95 % profile-likelihood interval.

Each fit is tested against no change (a permutation test of the best split's likelihood ratio,
permuted within scenes), and the p-values of every fit in the experiment are adjusted together
(Benjamini–Hochberg, as ``failure_modes`` does): a row is a boundary (``significant``, with
``boundary``, ``boundary_low`` and ``boundary_high`` set) only when ``q_value`` < 0.05. Where
accuracy does not change along the control beyond chance there is no boundary: those columns
are NULL and the fitted plateaus say what was seen.

A list is fitted as its values are ordered: with two values the boundary's interval is the
whole gap between them (the test still says whether the control matters), and more values, or
the ``boundary`` policy on a range, place it more finely. A parameter that covers a whole turn
(yaw over 360°, as a range or as a list spaced round the circle) has no below or above, and is
not fitted. The relation is computed
when asked (numpy, seconds at 10⁶ results): :func:`register_failure_boundaries` adds it to a
connection as ``failure_boundaries``; ``sweep3d query`` does so only for a statement naming it.
"""

from __future__ import annotations

import hashlib
import math
import re
from dataclasses import dataclass
from typing import Mapping, Sequence

import duckdb
import numpy as np
import pyarrow as pa

from sweep3d.results.compare import ALPHA
from sweep3d.results.measures import NOT_A_MEASURE
from sweep3d.results.quoting import identifier
from sweep3d.results.views import has_view
from sweep3d.spec import Choice, ControlInstance, Range
from sweep3d.stages.plan import fit_step

VIEW = "failure_boundaries"
#: The fewest counted results a group needs to be fitted.
MIN_RESULTS = 20
#: The fewest distinct values a group needs (with two, the boundary is somewhere between them).
MIN_VALUES = 2
_NAMED = re.compile(rf"\b{VIEW}\b", re.I)


@dataclass(frozen=True)
class Scale:
    """How a numeric parameter's values are spaced: ``log`` (a log range: the boundary is the
    geometric middle of its gap), ``wraps`` (a whole turn: not fitted)."""

    log: bool = False
    wraps: bool = False


def numeric_scales(controls: Sequence[ControlInstance]) -> dict[str, Scale]:
    """Column → :class:`Scale` of every parameter the spec gives a range or a list of numbers
    (two or more)."""
    out = {}
    for inst in controls:
        for param, space in inst.spaces.items():
            period = inst.control.periodic.get(param)
            if isinstance(space, Range):
                wraps = period is not None and space.high - space.low >= period
                out[f"{inst.id}_{param}"] = Scale(log=space.log, wraps=wraps)
            elif isinstance(space, Choice) and _numbers(space.options):
                out[f"{inst.id}_{param}"] = Scale(wraps=period is not None and _round_the_turn(space.options, period))
    return out


def _numbers(options: Sequence[object]) -> bool:
    """Whether ``options`` are two or more distinct finite numbers (not booleans)."""
    numbers = [o for o in options if isinstance(o, (int, float)) and not isinstance(o, bool)]
    return len(numbers) == len(options) and len(set(numbers)) >= 2 and all(math.isfinite(o) for o in numbers)


#: A list of a periodic parameter goes round the turn when the gap from its last value back to
#: its first is at most this many times its widest gap between neighbours.
ROUND_THE_TURN = 1.5


def _round_the_turn(options: Sequence[float], period: float) -> bool:
    """Whether listed values of a periodic parameter leave no "below" and "above": two values
    (either arc of the circle separates them), or values spaced round the circle, evenly or
    nearly (the gap from the last back to the first, across the period, at most
    :data:`ROUND_THE_TURN` times the widest gap between neighbours: yaw at -120, 0 and 120, or
    every 51° from 0 to 306; not 0, 30 and 60, nor 0, 90 and 180)."""
    values = sorted({float(o) for o in options})
    if len(values) <= 2:
        return True
    widest = max(b - a for a, b in zip(values, values[1:]))
    return period - (values[-1] - values[0]) <= ROUND_THE_TURN * widest


_SCHEMA = pa.schema([
    ("parameter", pa.string()), ("scope", pa.string()), ("object", pa.string()), ("environment", pa.string()),
    ("n", pa.int64()), ("values", pa.int64()), ("fails", pa.string()), ("boundary", pa.float64()),
    ("boundary_low", pa.float64()), ("boundary_high", pa.float64()), ("estimate", pa.float64()),
    ("interval_low", pa.float64()), ("interval_high", pa.float64()),
    ("accuracy_below", pa.float64()), ("n_below", pa.int64()),
    ("accuracy_above", pa.float64()), ("n_above", pa.int64()), ("level", pa.float64()), ("lr", pa.float64()),
    ("p_value", pa.float64()), ("permutations", pa.int64()), ("q_value", pa.float64()), ("significant", pa.bool_()),
    ("position", pa.int64()),
])


def failure_boundaries(con: duckdb.DuckDBPyConnection, scales: Mapping[str, Scale] | None = None) -> pa.Table:
    """Every fit (see the module) of the ``results`` view of ``con``, as a table.

    Args:
        scales: the numeric parameters (:func:`numeric_scales` of the spec's controls); None (no
            spec at hand) takes the numeric parameters with too many values to list (those the
            level views bin) as linear ranges.
    """
    rows = []
    for position, (column, scale) in enumerate(_fitted_parameters(con, scales)):
        rows += fit_parameter(column, scale, *_results(con, column), position=position)
    return pa.Table.from_pylist(adjust(rows), schema=_SCHEMA)


def fit_parameter(column: str, scale: Scale, x: np.ndarray, correct: np.ndarray, objects: np.ndarray,
                  environments: np.ndarray, position: int = 0) -> list[dict]:
    """The fits of one parameter (values ``x``, outcomes ``correct``, each result's object and
    environment) over all results, per object and per environment, as rows without q-values."""
    rows = []
    for scope, name, mask, strata in _groups(objects, environments):
        if mask.sum() < MIN_RESULTS or len(np.unique(x[mask])) < MIN_VALUES:
            continue
        fit = fit_step(x[mask], correct[mask], strata[mask], seed=_seed(column, scope, name))
        if fit is None:
            continue
        middle = (math.sqrt(fit.low_side * fit.high_side) if scale.log and fit.low_side > 0
                  else (fit.low_side + fit.high_side) / 2)
        rows.append({
            "parameter": column, "scope": scope, "object": name if scope == "object" else None,
            "environment": name if scope == "environment" else None, "n": fit.n, "values": fit.values,
            "fails": "below" if fit.accuracy_below < fit.accuracy_above else "above", "estimate": middle,
            "interval_low": fit.interval_low, "interval_high": fit.interval_high,
            "accuracy_below": fit.accuracy_below, "n_below": fit.n_below, "accuracy_above": fit.accuracy_above,
            "n_above": fit.n_above, "level": (fit.accuracy_below + fit.accuracy_above) / 2, "lr": fit.lr,
            "p_value": fit.p_value, "permutations": fit.permutations, "position": position,
        })
    return rows


def adjust(rows: list[dict]) -> list[dict]:
    """``rows`` (every fit of the experiment) with their Benjamini–Hochberg q-values and, where
    q < 0.05, the boundary and its interval (else those are None: no boundary)."""
    for row, q in zip(rows, _benjamini_hochberg([r["p_value"] for r in rows])):
        significant = q < ALPHA
        row.update(q_value=q, significant=significant, boundary=row["estimate"] if significant else None,
                   boundary_low=row["interval_low"] if significant else None,
                   boundary_high=row["interval_high"] if significant else None)
    return rows


def register_failure_boundaries(con: duckdb.DuckDBPyConnection, scales: Mapping[str, Scale] | None = None) -> None:
    """Compute :func:`failure_boundaries` and add it to ``con`` as the relation ``failure_boundaries``
    (nothing when ``con`` has no ``results``)."""
    if has_view(con, "results"):
        con.register(VIEW, failure_boundaries(con, scales))


def boundary_rows(con: duckdb.DuckDBPyConnection, scales: Mapping[str, Scale] | None = None) -> list[dict]:
    """The rows of ``failure_boundaries`` as registered on ``con`` (computed once by its caller),
    else computed, each as a dict by column name."""
    if has_view(con, VIEW):
        cursor = con.execute(f"FROM {VIEW}")
        names = [d[0] for d in cursor.description]
        return [dict(zip(names, row)) for row in cursor.fetchall()]
    return failure_boundaries(con, scales).to_pylist()


def names_boundaries(statement: str) -> bool:
    """Whether ``statement`` reads ``failure_boundaries`` (only then is it computed for a query)."""
    return bool(_NAMED.search(statement))


def _fitted_parameters(con: duckdb.DuckDBPyConnection, scales: Mapping[str, Scale] | None) -> list[tuple[str, Scale]]:
    """(column, scale) of each parameter to fit, in spec order."""
    if not has_view(con, "control_parameters"):
        return []
    listed = [r[0] for r in con.execute("SELECT parameter FROM control_parameters WHERE numeric AND parameter "
                                        f"NOT IN ('object', 'environment') AND {NOT_A_MEASURE} "
                                        "ORDER BY position").fetchall()]
    if scales is None:
        binned = {r[0] for r in con.execute("SELECT parameter FROM control_parameters WHERE binned").fetchall()}
        return [(column, Scale()) for column in listed if column in binned]
    return [(column, scales[column]) for column in listed if column in scales and not scales[column].wraps]


def _results(con: duckdb.DuckDBPyConnection, column: str) -> tuple[np.ndarray, ...]:
    """Value, correct, object and environment of the counted results where ``column`` is set."""
    got = con.execute(f"SELECT CAST({identifier(column)} AS DOUBLE) AS x, correct, object, environment FROM results "
                      f"WHERE counted AND isfinite(CAST({identifier(column)} AS DOUBLE))").fetchnumpy()
    return (np.asarray(got["x"], np.float64), np.asarray(got["correct"], bool),
            np.asarray(got["object"], object), np.asarray(got["environment"], object))


def _groups(objects: np.ndarray, environments: np.ndarray):
    """(scope, name, mask, strata) of each group to fit: all results (strata: scenes), each object
    (strata: environments) and each environment (strata: objects), the last two only when there
    are several objects (environments)."""
    scenes = np.unique(np.stack([objects.astype(str), environments.astype(str)], axis=1), axis=0,
                       return_inverse=True)[1].reshape(-1) if len(objects) else np.zeros(0, np.int64)
    yield "all", None, np.ones(len(objects), bool), scenes
    for scope, names, others in (("object", objects, environments), ("environment", environments, objects)):
        distinct = sorted(set(names.tolist()))
        if len(distinct) < 2:
            continue
        strata = np.unique(others.astype(str), return_inverse=True)[1] if len(others) else others
        for name in distinct:
            yield scope, name, names == name, strata


def _seed(*parts: str | None) -> int:
    """A seed fixed by the fit's names, so a fit's p-value does not depend on the other fits."""
    return int.from_bytes(hashlib.sha256(repr(parts).encode()).digest()[:8], "little")


def _benjamini_hochberg(p: list[float]) -> list[float]:
    """Benjamini–Hochberg q-values of ``p`` (in the same order)."""
    m = len(p)
    order = sorted(range(m), key=lambda i: p[i])
    q = [1.0] * m
    running = 1.0
    for rank in range(m, 0, -1):
        i = order[rank - 1]
        running = min(running, p[i] * m / rank)
        q[i] = min(1.0, running)
    return q


def boundary_phrase(row: Mapping) -> str:
    """What a significant fit says: ``fails below 12.1``; with two values, where the step can be
    anywhere between them, the value it fails at against the other (``fails at 5 against 35``)."""
    if row["values"] == 2:
        at, other = ((row["boundary_low"], row["boundary_high"]) if row["fails"] == "below"
                     else (row["boundary_high"], row["boundary_low"]))
        return f"fails at {control_number(at)} against {control_number(other)}"
    return f"fails {row['fails']} {control_number(row['boundary'])}"


def control_number(value: float) -> str:
    """A control value as findings and the report print it: three significant digits, no exponent below 10⁶."""
    return f"{value:.0f}" if 1e3 <= abs(value) < 1e6 else f"{value:.3g}"
