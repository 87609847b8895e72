"""Running an evaluator on a batch, and the checks on what it returns.

An evaluator is a plug-in: what it returns is checked before a row is written, so a broken one
stops the run in one line naming it (:class:`~sweep3d.core.errors.PluginError`, exit 2) instead of
writing rows that read as a verdict. The rows of earlier batches are kept (they are right);
the checks: one row per image, each a dict of the evaluator's own columns, each value of its
column's type, and ``valid`` and the verdict (the ``correct`` role) set on every valid row.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
import pyarrow as pa

from sweep3d.core import PLUGIN_FAILURES, PluginError, plugin_failure
from sweep3d.stages.infer.evaluators import Evaluator, Truth
from sweep3d.stages.infer.labels import LabelMap

#: What a verdict may be: Python's booleans, or numpy's (``ok and error.mean() < 0.1`` is one).
BOOLS = (bool, np.bool_)


def evaluate_checked(evaluator: Evaluator, kind: str, outputs: Any, truths: Sequence[Truth],
                     labels: LabelMap) -> list[dict]:
    """``evaluator.evaluate`` of one batch, its rows checked.

    Raises:
        PluginError: the evaluator raised, or returned rows that break its declaration.
    """
    try:
        rows = evaluator.evaluate(outputs, truths, labels)
    except PLUGIN_FAILURES as exc:  # a user's code: whatever it raises, or an exit, is its failure
        raise plugin_failure(f"evaluator {kind}", exc, during="in evaluate()") from None
    problem = rows_problem(evaluator, rows, len(truths))
    if problem is not None:  # where the plug-in is written: read from its source only now (2 ms a batch)
        raise PluginError(f"evaluator {kind} ({type(evaluator).where()}) {problem}")
    return rows


def rows_problem(evaluator: Evaluator, rows: Any, images: int) -> str | None:
    """What is wrong with ``rows`` as ``evaluator``'s rows for ``images`` images (None: nothing)."""
    if not isinstance(rows, list) or not all(isinstance(row, dict) for row in rows):
        return f"returned {type(rows).__name__}, not a list of one dict per image"
    if len(rows) != images:
        return f"returned {len(rows)} rows for {images} images; return one row per image, in order"
    schema = evaluator.schema
    for i, row in enumerate(rows):
        unknown = [key for key in row if key not in schema.names]
        if unknown:
            return (f"returned column {unknown[0]!r} (row {i}), which is not in its schema "
                    f"({', '.join(schema.names)}); declare it or leave it out")
    for field in schema:
        try:
            pa.array([row.get(field.name) for row in rows], type=field.type)
        except (pa.ArrowException, ValueError, TypeError, OverflowError):
            bad = next((row.get(field.name) for row in rows if not _fits(row.get(field.name), field.type)), None)
            return f"returned {field.name} = {bad!r}, which is not {field.type} as its schema says"
    roles = evaluator.roles
    for i, row in enumerate(rows):
        if not isinstance(row.get(roles.valid), BOOLS):
            return f"returned no {roles.valid!r} in row {i}; every row says whether it is valid (true or false)"
        if row[roles.valid] and not isinstance(row.get(roles.correct), BOOLS):
            return (f"returned no {roles.correct!r} in valid row {i} (its correctness column); set it to "
                    "true or false, or the row to valid = false")
    return None


def _fits(value: Any, kind: pa.DataType) -> bool:
    try:
        pa.array([value], type=kind)
        return True
    except (pa.ArrowException, ValueError, TypeError, OverflowError):
        return False
