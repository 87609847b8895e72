"""The ``counterfactuals`` views: what ``sweep3d explain`` found, queryable like the results.

``explain`` keeps one row per failure it searched in the store's ``counterfactuals`` table
(:data:`COUNTERFACTUALS`, declared by :mod:`sweep3d.followups.explain.stored`, which writes it);
its fixing jobs are not the experiment's jobs (they would tilt every accuracy towards right
answers), so they live there and in the keyed stage tables only. A store written before the table
kept them in ``<store>/explain/<experiment>.parquet`` (:func:`legacy_counterfactuals_path`): the
views read that file while the table holds no row of the experiment.

Views (only once ``explain`` has run):

``counterfactuals``
    one row per failure searched: the failure's job, scene, keys, what the model said
    (``failure_label``, ``failure_loss``, ``failure_probability`` of the true class,
    ``failure_margin``: its probability less the best other class's), whether a fix was found
    (``found``) and the search ran to its end (``complete``: false when the budget stopped it),
    the fixing configuration's keys and verdict (``fix_*``, the same measures), the parameters
    changed (``parameters``, ``from_values``, ``to_values``, ``deltas`` in the parameter's own
    units, NULL for a text option; ``shares``, signed shares of the range), their normalised
    ``distance`` (Euclidean over the shares) and ``change``, the move written out; whether the fix
    is fragile by the stability check's rule (``fix_fragile``, NULL before a check; the check's
    ``fragile_threshold``), the probes past a fragile nearest fix (``further_probes``) and, where
    a sturdier fix further along replaced it, that nearest fix (``nearest_distance``,
    ``nearest_margin``, ``nearest_change``); the search's ``resolution`` (a share of each range)
    and ``resolutions`` (in each changed parameter's units, NULL for an option); and the
    ``sentence`` the console and the report print.
``counterfactual_parameters``
    per parameter: ``cheapest`` (how many found fixes change it), ``alone`` (of which change
    nothing else), ``share`` (of the found fixes), and the median absolute share it moves.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path
from typing import Sequence

import duckdb
import pyarrow as pa
import pyarrow.parquet as pq

from sweep3d.cache import Store, safe_filename, store_error
from sweep3d.results.quoting import literal

COUNTERFACTUAL_VIEWS = ("counterfactuals", "counterfactual_parameters")

#: The store's table of what ``explain`` found, one row per (experiment, failure).
COUNTERFACTUALS = "counterfactuals"

_MEASURES = [("label", pa.string()), ("correct", pa.bool_()), ("loss", pa.float64()),
             ("probability", pa.float64()), ("margin", pa.float64())]

SCHEMA = pa.schema([
    ("experiment", pa.string()), ("model", pa.string()), ("failure_job", pa.int64()),
    ("object", pa.string()), ("environment", pa.string()), ("true_labels", pa.string()),
    ("failure_pred_key", pa.string()), ("failure_image_key", pa.string()),
    *[(f"failure_{name}", kind) for name, kind in _MEASURES],
    ("found", pa.bool_()), ("complete", pa.bool_()), ("probes", pa.int64()),
    ("fix_render_key", pa.string()), ("fix_image_key", pa.string()), ("fix_pred_key", pa.string()),
    *[(f"fix_{name}", kind) for name, kind in _MEASURES],
    ("parameters", pa.list_(pa.string())), ("from_values", pa.list_(pa.string())),
    ("to_values", pa.list_(pa.string())), ("deltas", pa.list_(pa.float64())), ("shares", pa.list_(pa.float64())),
    ("n_changed", pa.int64()), ("distance", pa.float64()), ("change", pa.string()),
    ("seed", pa.int64()), ("budget", pa.int64()),
    # what a user needs to trust the fix (added later: older files lack them, and read as before)
    ("fix_fragile", pa.bool_()), ("fragile_threshold", pa.float64()), ("further_probes", pa.int64()),
    ("nearest_distance", pa.float64()), ("nearest_margin", pa.float64()), ("nearest_change", pa.string()),
    ("resolution", pa.float64()), ("resolutions", pa.list_(pa.float64())), ("sentence", pa.string()),
])


#: The SQL type of each Arrow type of :data:`SCHEMA`, for a column an older file lacks.
_SQL_TYPES = {"string": "VARCHAR", "bool": "BOOLEAN", "int64": "BIGINT", "double": "DOUBLE",
              "list<item: double>": "DOUBLE[]", "list<item: string>": "VARCHAR[]"}


def legacy_counterfactuals_path(store: Store, experiment: str) -> Path:
    """Where ``explain`` kept an experiment's counterfactuals before the ``counterfactuals`` table."""
    return store.root / "explain" / f"{safe_filename(experiment)}.parquet"


def register_counterfactual_views(con: duckdb.DuckDBPyConnection, store: Store, experiment: str | None,
                                  segments: Sequence[Path] = ()) -> list[Path]:
    """Create the views over ``experiment``'s rows of the ``counterfactuals`` table (its readable
    ``segments``), or of a store's older file while the table holds none of them; no views when
    ``explain`` has not run for it (the store's view over other experiments' rows is dropped).
    Returns the files the views read beyond the table's segments (the older file, when read)."""
    if experiment is None:
        return []
    where = f"experiment = {literal(experiment)}"
    source = f"read_parquet([{', '.join(literal(str(p)) for p in segments)}], union_by_name = true)"
    if segments and con.execute(f"SELECT count(*) FROM {source} WHERE {where}").fetchone()[0]:
        _create(con, source, where, dedupe=True)
        return []
    con.execute(f"DROP VIEW IF EXISTS {COUNTERFACTUALS}")  # the table's rows are other experiments'
    path = legacy_counterfactuals_path(store, experiment)
    try:
        if "failure_job" not in pq.read_schema(path).names:
            return []
    except OSError as exc:
        if isinstance(exc, PermissionError) or exc.errno in (errno.EACCES, errno.EPERM):
            code = exc.errno or errno.EACCES  # there, but not for us: said, not "no such table"
            raise store_error(OSError(code, os.strerror(code), str(path)), "read") from None
        return []  # none yet
    except (ValueError, pa.ArrowException):  # not a table explain wrote: no views
        return []
    _create(con, f"read_parquet({literal(str(path))})", "true", dedupe=False)
    return [path]


def _create(con: duckdb.DuckDBPyConnection, source: str, where: str, dedupe: bool) -> None:
    """The two views over ``source``'s rows that ``where`` keeps (``dedupe``: a key's newest row)."""
    names = {row[0] for row in con.execute(f"DESCRIBE SELECT * FROM {source}").fetchall()}
    own = " AND failure_pred_key IN (SELECT pred_key FROM jobs)" if _has(con, "jobs") else ""
    newest = " QUALIFY row_number() OVER (PARTITION BY counterfactual_key ORDER BY created_at DESC) = 1" if dedupe \
        else ""
    # a file or segment from before a column was added reads that column as NULL
    later = "".join(f", NULL::{_SQL_TYPES[str(f.type)]} AS {f.name}" for f in SCHEMA if f.name not in names)
    con.execute(f"CREATE OR REPLACE VIEW {COUNTERFACTUALS} AS SELECT *{later} FROM {source} "
                f"WHERE {where}{own}{newest} ORDER BY failure_job")  # a failure the spec no longer plans is not shown
    con.execute("""CREATE OR REPLACE VIEW counterfactual_parameters AS
        WITH moves AS (
            SELECT failure_job, n_changed, unnest(parameters) AS parameter, unnest(shares) AS share
            FROM counterfactuals WHERE found),
        fixes AS (SELECT count(*) AS n FROM counterfactuals WHERE found)
        SELECT parameter, count(*) AS cheapest, count(*) FILTER (WHERE n_changed = 1) AS alone,
               count(*) / (SELECT n FROM fixes) AS share, median(abs(share)) AS median_share
        FROM moves GROUP BY parameter ORDER BY cheapest DESC, parameter""")


def _has(con: duckdb.DuckDBPyConnection, view: str) -> bool:
    return bool(con.execute("SELECT count(*) FROM duckdb_views() WHERE view_name = ?", [view]).fetchone()[0])


