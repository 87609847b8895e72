"""``results``' class names as the spec wrote them, with the model's own names beside them.

A prediction row holds the model's names for classes (``top1_label = 'sneaker'``) and is shared
by every experiment whose job has its key, whatever each spec called the class; the plan records
the classes its spec names otherwise (:data:`~sweep3d.spec.columns.CLASS_NAMES_METADATA`), so
``results`` prints those by the spec's name (``'running shoe'``), and a label written in the spec
finds its rows. The model's names stay beside them (:data:`~sweep3d.spec.columns.MODEL_NAME_COLUMNS`).

A class is matched by its id where the row has one (``top1``, ``topk``: the ranked evaluators),
else by the model's name, unless another class of the model shares that name (then it keeps the
model's name: only an id could tell the two apart).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

import duckdb
import pyarrow as pa
import pyarrow.parquet as pq

from sweep3d.results.quoting import identifier, literal
from sweep3d.spec import CLASS_NAMES_METADATA, MODEL_NAME_COLUMNS

#: (class id, the model's name, the spec's name, whether another class has the model's name too)
Renamed = tuple[int, str, str, bool]
#: DuckDB 1.3 introduced ``lambda x: …`` and DuckDB 2 refuses the older ``x -> …``.
_NEW_LAMBDA = tuple(int(part) for part in duckdb.__version__.split(".")[:2] if part.isdigit()) >= (1, 3)


def read_class_names(jobs: Path) -> dict[str, list[Renamed]]:
    """Per model, the classes the plan at ``jobs`` names otherwise than the model (empty for a
    plan from before plans recorded them, or one whose record does not read)."""
    try:
        raw = (pq.read_schema(jobs).metadata or {}).get(CLASS_NAMES_METADATA)
        data = json.loads(raw) if raw is not None else {}
        return {str(model): [(int(i), str(own), str(name), bool(shared)) for i, own, name, shared in rows]
                for model, rows in data.items()}
    except (OSError, ValueError, TypeError, AttributeError, pa.ArrowException):
        return {}


def named_columns(have: dict[str, str], columns: Sequence[str], prediction: str | None,
                  names: dict[str, list[Renamed]], own_model: bool) -> dict[str, str]:
    """The SELECT expression of each class-name column of ``results`` (``p.`` the predictions,
    ``j.`` the jobs; ``have``: the predictions' columns and their types; ``columns``: the
    evaluator's; ``prediction``: its prediction role's column; ``own_model``: jobs name their
    model), keyed by the column it makes: the names as the spec wrote them under the column's
    own name and its usual one (``top1_label``), the model's under ``top1_model_label`` and
    ``topk_model_labels``. Only columns that are there."""
    out: dict[str, str] = {}
    if prediction is not None and prediction in have and have[prediction] == "VARCHAR":
        raw = f"p.{identifier(prediction)}"
        by_id = prediction == "top1_label" and _is_int(have.get("top1"))
        subject = "p.top1" if by_id else raw
        renamed = _renamed(subject, raw, names, by_id, own_model)
        for column in {prediction, "top1_label"}:
            out[column] = renamed
        out[MODEL_NAME_COLUMNS["top1_label"]] = raw
    if "topk_labels" in columns and have.get("topk_labels") == "VARCHAR[]":
        by_id = have.get("topk") is not None and _is_int(have["topk"].removesuffix("[]")) and "topk" in columns
        subject, otherwise, params = ("c", "p.topk_labels[i]", "c, i") if by_id else ("x", "x", "x")
        body = _renamed(subject, otherwise, names, by_id, own_model)
        listed = "p.topk" if by_id else "p.topk_labels"
        out["topk_labels"] = "p.topk_labels" if body == otherwise else f"list_transform({listed}, {_lambda(params, body)})"
        out[MODEL_NAME_COLUMNS["topk_labels"]] = "p.topk_labels"
    return out


def _renamed(subject: str, otherwise: str, names: dict[str, list[Renamed]], by_id: bool, own_model: bool) -> str:
    """``otherwise`` (the model's name), or the spec's name of the class ``subject`` is (its id, or
    its model's name), for the row's model."""
    cases = {model: _case(subject, [(str(int(i)) if by_id else literal(own), literal(name))
                                    for i, own, name, shared in rows if by_id or not shared], otherwise)
             for model, rows in names.items()}
    cases = {model: case for model, case in cases.items() if case != otherwise}
    if not cases:
        return otherwise
    distinct = set(cases.values())
    if len(distinct) == 1 and (not own_model or len(cases) == len(names)):
        return distinct.pop()  # every model names its classes alike (or jobs name no model)
    if not own_model:
        return otherwise  # several models' names and no way to tell rows apart: the models' own
    return _case("j.model", [(literal(model), case) for model, case in cases.items()], otherwise)


def _case(subject: str, pairs: list[tuple[str, str]], otherwise: str) -> str:
    if not pairs:
        return otherwise
    return f"(CASE {subject} " + " ".join(f"WHEN {k} THEN {v}" for k, v in pairs) + f" ELSE {otherwise} END)"


def _lambda(params: str, body: str) -> str:
    return f"lambda {params}: {body}" if _NEW_LAMBDA else f"({params}) -> {body}"


def _is_int(kind: str | None) -> bool:
    return kind in ("TINYINT", "SMALLINT", "INTEGER", "BIGINT", "UTINYINT", "USMALLINT", "UINTEGER", "UBIGINT")
