"""Which results an export takes, and the checked bytes of their images and masks.

The user's ``--where`` is a condition over ``results``' columns, checked by DuckDB's own parser
before anything runs: it must leave ``SELECT * FROM results WHERE (…)`` one plain SELECT that
differs from ``… WHERE (true)`` only in its condition, so a second statement, a ``UNION`` or an
``ORDER BY`` smuggled in with a closing parenthesis is refused. The query then runs on the
read-only connection ``sweep3d query`` uses (only the store's view files may be opened).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import duckdb
import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from sweep3d.cache import Store, sha256_bytes
from sweep3d.core import UserError
from sweep3d.results import arrow, results_connection, results_store, stored_parameters
from sweep3d.spec import LoadedSpec

#: What an export takes when no ``--where`` is given: the failures.
DEFAULT_WHERE = "NOT correct"
#: What ``--unevaluable`` may say about jobs whose ``evaluable`` is false.
UNEVALUABLE = ("skip", "flag")
#: Columns the selection query adds to each row (the recorded digests of its blobs); not ``results``' own.
IMAGE_DIGEST, MASK_DIGEST = "_export_image_sha256", "_export_mask_sha256"
_WHERE_HINT = "give one condition over results' columns, e.g. --where \"NOT correct AND object = 'mug'\""


def check_where(condition: str) -> str:
    """``condition`` if it is one SQL condition over ``results``' columns (its columns are only
    known to exist once it runs).

    Raises:
        UserError: it is empty, does not parse, holds more than one statement, or adds anything
            to the query but a condition (a ``UNION``, ``ORDER BY``, ``LIMIT`` after a ``)``).
    """
    if not condition.strip():
        raise UserError(f"--where is empty: {_WHERE_HINT}")
    statement = _wrapped(condition)
    try:
        parsed = duckdb.extract_statements(statement)
        if len(parsed) != 1:
            raise UserError(f"--where {condition!r} holds {len(parsed)} statements: {_WHERE_HINT}")
        if parsed[0].type != duckdb.StatementType.SELECT or _shape(statement) != _shape(_wrapped("true")):
            raise UserError(f"--where {condition!r} is not only a condition: {_WHERE_HINT}")
    except duckdb.Error as exc:
        if ";" in condition:
            raise UserError(f"--where {condition!r} holds a ';': {_WHERE_HINT}") from None
        raise UserError(f"--where {condition!r} does not parse ({str(exc).splitlines()[0]}): {_WHERE_HINT}") from None
    return condition


def _wrapped(condition: str) -> str:
    # the newlines keep a trailing ``--`` comment from swallowing the closing parenthesis
    return f"SELECT * FROM results WHERE (\n{condition}\n)"


def _shape(statement: str) -> dict:
    """DuckDB's parse tree of ``statement`` without its WHERE clause (a parse error raises)."""
    con = duckdb.connect()
    try:
        tree = json.loads(con.execute("SELECT json_serialize_sql(?)", [statement]).fetchone()[0])
    finally:
        con.close()
    if tree.get("error"):
        raise duckdb.ParserException(tree.get("error_message", "syntax error"))
    nodes = [s["node"] for s in tree["statements"]]
    for node in nodes:
        node.pop("where_clause", None)
    return {"nodes": nodes}


@dataclass(frozen=True)
class Selection:
    """The rows an export takes, in job order, and what it needs to describe them.

    Attributes:
        table: the rows as DuckDB gave them (its column types), with the blobs' digests.
        rows: one dict per result, every column of ``results`` (and the blobs' digests).
        columns: ``results``' columns, in order.
        parameters: the control-parameter columns, as the experiment's plan lists them.
        skipped: results the condition chose that were left out as not evaluable.
        truth: ``results`` has the truth passes' columns (a mask per job).
    """

    table: pa.Table
    rows: list[dict[str, Any]]
    columns: list[str]
    parameters: list[str]
    skipped: int
    truth: bool


def select(spec: LoadedSpec, condition: str, model: str | None, unevaluable: str) -> Selection:
    """The results of ``spec``'s experiment (``model``'s; default its first) meeting ``condition``.

    Args:
        unevaluable: ``skip`` leaves out jobs whose ``evaluable`` is false; ``flag`` keeps them.

    Raises:
        UserError: no results yet, or the condition fails to run (an unknown column, a type error).
    """
    with results_store(spec, warn=False) as store, results_connection(spec, model, store=store) as con:
        have = [name for name, *_ in con.execute("DESCRIBE results").fetchall()]
        views = {name for name, in con.execute("SELECT view_name FROM duckdb_views() WHERE NOT internal").fetchall()}
        gate = "evaluable IS FALSE" if "evaluable" in have else "false"
        chosen = f"SELECT *, ({gate}) AS _export_unevaluable FROM results WHERE (\n{condition}\n)"
        image = ["NULL"]
        for view, key in (("images", "image_key"), ("renders", "render_key")):
            if view in views:
                image.insert(-1, f"(SELECT v.sha256 FROM {view} v WHERE v.{key} = c.image_key LIMIT 1)")
        mask = ("(SELECT t.mask_sha256 FROM truths t WHERE t.truth_key = c.truth_key LIMIT 1)"
                if "truth_key" in have and "truths" in views else "NULL")
        query = (f"WITH chosen AS ({chosen}) SELECT c.*, coalesce({', '.join(image)}) AS {IMAGE_DIGEST}, "
                 f"{mask} AS {MASK_DIGEST} FROM chosen c ORDER BY c.job")
        try:
            table = arrow(con, query)
        except duckdb.Error as exc:  # an unknown column, a type mismatch: the condition's, since ours are fixed
            raise UserError(f"--where {condition!r} failed: {str(exc).splitlines()[0]} (`sweep3d query SPEC "
                            "\"DESCRIBE results\"` lists the columns)") from None
        parameters = stored_parameters(store.jobs_path(spec.name))
    rows_before = table.num_rows
    if unevaluable == "skip":
        table = table.filter(pc.invert(pc.fill_null(table.column("_export_unevaluable"), False)))
    skipped = rows_before - table.num_rows
    table = table.drop_columns(["_export_unevaluable"])
    if parameters is None:
        parameters = [c for c in spec.parameter_columns if c in have]
    return Selection(table, table.to_pylist(), have, parameters, skipped, "truth_key" in have)


def image_bytes(store: Store, row: dict[str, Any]) -> bytes:
    """The stored image of ``row`` (what the model saw), checked against its recorded digest.

    Raises:
        UserError: the blob is missing or no longer matches its digest.
    """
    return _blob(store, row, row["image_key"], "png", row.get(IMAGE_DIGEST), "image")


def mask_of(store: Store, row: dict[str, Any]) -> np.ndarray:
    """The mask pass of ``row`` (bool (H, W): the object's visible pixels), checked against its digest.

    Raises:
        UserError: the job has no truth row yet, or its mask blob is missing or damaged.
    """
    from sweep3d.core import BLOB_SUFFIX, decode_mask

    if row.get("truth_key") is None or row.get(MASK_DIGEST) is None:
        raise UserError(f"job {row['job']} of {row['experiment']} has no mask yet: run `sweep3d run` on the spec "
                        "again to render its truth passes, then export")
    return decode_mask(_blob(store, row, row["truth_key"], BLOB_SUFFIX["mask"], row[MASK_DIGEST], "mask"))


def _blob(store: Store, row: dict[str, Any], key: str, ext: str, digest: str | None, what: str) -> bytes:
    path = store.blob_path(key, ext)
    try:
        data = path.read_bytes()
    except OSError as exc:
        problem = "is missing" if isinstance(exc, FileNotFoundError) else f"cannot be read ({exc.strerror})"
        data, damaged = b"", problem
    else:
        damaged = "no longer matches its recorded digest" if digest and sha256_bytes(data) != digest else ""
    if damaged:
        raise UserError(f"the {what} of job {row['job']} ({path}) {damaged}: run `sweep3d run` on the spec again "
                        "to make it anew, then export")
    return data
