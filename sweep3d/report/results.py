"""The experiment's results as columns: what the explorer and the example galleries draw from.

Rows are ordered wrong first (highest loss first), then correct, then invalid, so the first
rows of any slice are its most telling failures. Each parameter's value is its *level* in the
``control_levels`` view (a value, or a bin of a many-valued numeric parameter).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import duckdb
import numpy as np

WRONG, CORRECT, INVALID = 0, 1, 2  # outcome codes
OUTCOME_NAMES = ("wrong", "correct", "invalid")


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


@dataclass
class ResultTable:
    """Every result of the experiment (N rows), column by column.

    Attributes:
        parameters: the parameters, in spec order.
        levels: int32 array (P, N): the level of each result in each parameter.
        job: int64 array (N,): job index.
        outcome: int8 array (N,): :data:`WRONG`, :data:`CORRECT` or :data:`INVALID`.
        loss: float64 array (N,): the evaluator's loss (NaN where there is none).
        prediction: N top-1 labels (None where the prediction is invalid).
        image_key: N image keys.
    """

    parameters: list[Parameter]
    levels: np.ndarray
    job: np.ndarray
    outcome: np.ndarray
    loss: np.ndarray
    prediction: list[str | None]
    image_key: list[str]

    def __len__(self) -> int:
        return len(self.job)

    def parameter(self, name: str) -> int:
        """The row of ``levels`` that holds parameter ``name``."""
        return next(i for i, p in enumerate(self.parameters) if p.name == name)

    def mask(self, where: Mapping[str, int]) -> np.ndarray:
        """Boolean (N,) array of the results at the given level of each named parameter."""
        selected = np.ones(len(self), dtype=bool)
        for name, level in where.items():
            selected &= self.levels[self.parameter(name)] == level
        return selected

    def examples(self, selected: np.ndarray, limit: int, outcome: int = WRONG) -> list[int]:
        """Up to ``limit`` row indices among ``selected`` with ``outcome``, most telling first."""
        return np.flatnonzero(selected & (self.outcome == outcome))[:limit].tolist()


def load_results(con: duckdb.DuckDBPyConnection, names: Sequence[str]) -> ResultTable:
    """Read the results and the levels of the parameters ``names`` (unknown names are skipped).

    Args:
        con: a connection from ``aggregate.connect`` (with the aggregate views).
        names: parameter names in the order wanted, e.g. ``object``, ``environment``, then the
            spec's control columns.
    """
    columns = {row[0] for row in con.execute("DESCRIBE results").fetchall()}
    prediction = "top1_label" if "top1_label" in columns else "NULL::VARCHAR"
    loss = "loss" if "loss" in columns else "NULL::DOUBLE"
    rows = con.execute(
        f"SELECT job, CASE WHEN NOT valid THEN {INVALID} WHEN correct THEN {CORRECT} ELSE {WRONG} END AS outcome, "
        f"{loss} AS loss, {prediction} AS prediction, image_key FROM results "
        f"ORDER BY outcome = {INVALID}, outcome, loss DESC NULLS LAST, job"
    ).fetchnumpy()
    job = np.asarray(rows["job"], dtype=np.int64)

    known = {r[0]: r[1:] for r in con.execute(
        "SELECT parameter, numeric, binned FROM control_parameters").fetchall()}
    order = [name for name in names if name in known]
    labels: dict[str, list[str]] = {name: [] for name in order}
    for name, label in con.execute(
            "SELECT parameter, label FROM control_accuracy WHERE list_contains(?, parameter) ORDER BY level",
            [order]).fetchall():
        labels[name].append(label)
    parameters = [Parameter(name, labels[name], bool(known[name][0]), bool(known[name][1])) for name in order]

    levels = np.full((len(order), len(job)), -1, dtype=np.int32)
    if order and len(job):
        found = con.execute(
            "SELECT job, parameter, level FROM control_levels WHERE list_contains(?, parameter)", [order]
        ).fetchnumpy()
        by_job = np.argsort(job)
        rows_of = by_job[np.searchsorted(job[by_job], np.asarray(found["job"], dtype=np.int64))]
        index = {name: i for i, name in enumerate(order)}
        params = np.array([index[p] for p in found["parameter"]], dtype=np.int64)
        levels[params, rows_of] = np.asarray(found["level"], dtype=np.int32)
    return ResultTable(
        parameters=parameters,
        levels=levels,
        job=job,
        outcome=np.asarray(rows["outcome"], dtype=np.int8),
        loss=np.asarray([np.nan if v is None else v for v in _values(rows["loss"])], dtype=np.float64),
        prediction=[None if v is None else str(v) for v in _values(rows["prediction"])],
        image_key=[str(v) for v in _values(rows["image_key"])],
    )


def _values(column: np.ndarray) -> list:
    """A fetched column as a Python list, masked entries as None."""
    if isinstance(column, np.ma.MaskedArray):
        return column.astype(object).filled(None).tolist()
    return column.tolist()
