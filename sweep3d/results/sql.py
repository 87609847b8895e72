"""A user's SQL over an experiment's views, read-only: what ``sweep3d query`` and the Python
API's ``sql`` share (the statement check, the locked-down connection, one-line errors)."""

from __future__ import annotations

from contextlib import contextmanager, nullcontext
from pathlib import Path
from typing import Iterator, Sequence

import duckdb
import pyarrow as pa

from sweep3d.cache import Store, is_select
from sweep3d.core import UserError
from sweep3d.results.boundaries import names_boundaries, numeric_scales, register_failure_boundaries
from sweep3d.results.own_jobs import results_store
from sweep3d.results.rules import names_rules, register_rules
from sweep3d.results.views import connect, has_view, no_results
from sweep3d.spec import LoadedSpec

QUERY_HINT = ("sweep3d query runs one SELECT over the views results, jobs, predictions, renders, images, runs, "
              "control_accuracy, failure_modes, ...; the list: docs/how-to/query.md")


def select_only(sql: str, refusal_hint: str = "write rows to a file with --output FILE") -> str:
    """``sql`` without its trailing semicolons, if DuckDB parses it as one read-only query.

    A query shared in a notebook or a script must not change or leak files: COPY, ATTACH,
    INSTALL, SET and the like are refused here, before the connection (locked to the store's
    files) would refuse most of them anyway.
    """
    statement = sql.strip().rstrip(";").strip()
    try:
        if is_select(statement):
            return statement
        kinds = [s.type.name for s in duckdb.extract_statements(statement)]
    except duckdb.Error as exc:
        raise UserError(f"query failed: {str(exc).splitlines()[0]} ({QUERY_HINT})") from None
    what = kinds[0] if len(kinds) == 1 else f"{len(kinds)} statements" if kinds else "an empty query"
    raise UserError(f"query refused {what}: {QUERY_HINT}; {refusal_hint}")


@contextmanager
def results_connection(spec: LoadedSpec, model: str | None = None, writable: Sequence[Path] = (),
                       statement: str = "", store: Store | None = None) -> Iterator[duckdb.DuckDBPyConnection]:
    """A read-only connection over the views of ``spec``'s own results (``model``'s, default the
    first model's; ``store``: a :func:`results_store` of ``spec`` the caller holds); a DuckDB error
    inside the block becomes one line (no results yet: how to make them), and so does a store
    file that cannot be read (the answer would leave out its rows: refused, never given in part). ``failure_boundaries``
    and ``rules`` (computed in Python, seconds at scale) are added only when ``statement`` names
    them, so other queries cost what they did."""
    with nullcontext(store) if store is not None else results_store(spec, warn=False) as own:
        with _connection(spec, own, model, writable, statement) as con:
            yield con


@contextmanager
def _connection(spec: LoadedSpec, store: Store, model: str | None, writable: Sequence[Path],
                statement: str) -> Iterator[duckdb.DuckDBPyConnection]:
    con = connect(store, spec.name, read_only=True, writable=writable, model=model)
    try:
        store.require_readable(spec.path)  # rows read around a file it could not read are no answer
        if names_boundaries(statement):
            register_failure_boundaries(con, numeric_scales(spec.controls))
        if names_rules(statement):
            register_rules(con)
        yield con
    except duckdb.Error as exc:
        if isinstance(exc, duckdb.CatalogException) and not has_view(con, "results"):
            raise no_results(store, spec.name, spec.path) from None
        raise UserError(f"query failed: {str(exc).splitlines()[0]} ({QUERY_HINT})") from None
    finally:
        con.close()


def arrow(con: duckdb.DuckDBPyConnection, statement: str) -> pa.Table:
    """Every row of ``statement`` as a pyarrow Table (DuckDB 1.x and 2.x)."""
    relation = con.sql(statement)
    return relation.to_arrow_table() if hasattr(relation, "to_arrow_table") else relation.arrow()
