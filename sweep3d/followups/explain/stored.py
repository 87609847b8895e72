"""What ``sweep3d explain`` keeps in the store: the ``counterfactuals`` table, declared once, here.

One row per (experiment, failure searched) under its ``counterfactual_key``. Each explain run
writes the experiment's rows anew: a newer row of each failure it searched, which counts
("newest"), and the rows of failures it did not search are dropped, so the table holds what the
latest explain of each experiment found (as the ``counterfactuals`` views show it, and the report's
panel counts it). The store knows the table only by this contract (the package root names this
module): ``query``, ``cache verify``, ``compact``, ``gc`` and ``stats`` see it as any other.

Stores written before the table kept a Parquet file per experiment under ``explain/``
(:func:`sweep3d.results.legacy_counterfactuals_path`): the views read it while the table holds
no row of the experiment, and the next explain removes it; the folder stays declared, so a
folder holding it is still known for a store's.
"""

from __future__ import annotations

import hashlib
import json
from datetime import datetime, timezone
from typing import Any

import pyarrow as pa

from sweep3d.cache import Store, TableContract, register_store_folder, register_table, utc_now
from sweep3d.results import COUNTERFACTUALS, SCHEMA, legacy_counterfactuals_path

#: One row of the table: the views' columns (:data:`sweep3d.results.SCHEMA`), its key and when it was written.
TABLE_SCHEMA = pa.schema([("counterfactual_key", pa.string()), *SCHEMA,
                          ("created_at", pa.timestamp("us", tz="UTC"))])
LEGACY_FOLDER = "explain"
_EARLIEST = datetime.min.replace(tzinfo=timezone.utc)


def counterfactual_key(experiment: str, failure_pred_key: str) -> str:
    """The table's key: the failure (its prediction's key) of one experiment."""
    return hashlib.sha256(json.dumps([experiment, failure_pred_key]).encode()).hexdigest()


def write_counterfactuals(store: Store, experiment: str, rows: list[dict[str, Any]]) -> bool:
    """Make ``rows`` (one per failure searched, :data:`SCHEMA`'s columns) the experiment's rows of
    the table; call it holding the store's writer lock. Rows the table already holds as they are
    (a rerun that found the same) are not written again. Returns whether anything changed."""
    keyed = {counterfactual_key(experiment, row["failure_pred_key"]): row for row in rows}
    held = _held(store, experiment)
    fresh = {key: row for key, row in keyed.items() if held.get(key) != _values(row)}
    now = utc_now()
    store.append(COUNTERFACTUALS, [{"counterfactual_key": key, **row, "created_at": now}
                                   for key, row in fresh.items()], TABLE_SCHEMA)
    dropped = store.drop_rows(COUNTERFACTUALS, set(held) - set(keyed))  # after the new rows are in
    legacy_counterfactuals_path(store, experiment).unlink(missing_ok=True)
    return bool(fresh or dropped)


def _held(store: Store, experiment: str) -> dict[str, dict[str, Any]]:
    """Key → the values of its newest row, for the experiment's rows in the table."""
    data = store.table(COUNTERFACTUALS)
    if data is None:
        return {}
    newest: dict[str, dict[str, Any]] = {}
    mine = [row for row in data.to_pylist() if row.get("experiment") == experiment]
    for row in sorted(mine, key=lambda r: r["created_at"] or _EARLIEST):  # the newest last
        newest[row["counterfactual_key"]] = _values(row)
    return newest


def _values(row: dict[str, Any]) -> dict[str, Any]:
    return {name: row.get(name) for name in SCHEMA.names}


COUNTERFACTUALS_TABLE = register_table(TableContract(COUNTERFACTUALS, key="counterfactual_key",
                                                           columns=tuple(TABLE_SCHEMA.names), merge="newest"))
register_store_folder(LEGACY_FOLDER)
