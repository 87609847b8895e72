"""Running a user's SQL over the store's files safely: one read-only statement, reading only them."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

import duckdb


def lock_down(con: duckdb.DuckDBPyConnection, readable: Iterable[Path], writable: Iterable[Path] = ()) -> None:
    """Let ``con`` open only the files ``readable`` and ``writable`` from now on, and change no setting.

    For SQL from users (``sweep3d query``): a statement then cannot read other files, attach a
    database file, install or load an extension, spill to a temp folder or undo this. DuckDB's
    allow-list does not tell reading from writing, so a ``COPY`` or ``ATTACH`` could still write
    the listed files themselves: run only user statements that :func:`is_select` accepts.
    """
    allowed = sorted({variant for p in [*readable, *writable] for variant in (os.path.abspath(p), os.path.realpath(p))})
    con.execute("SET temp_directory = ''")  # its folder would be allowed, writes included
    con.execute(f"SET allowed_paths = [{', '.join(_sql_str(p) for p in allowed)}]")
    con.execute("SET enable_external_access = false")
    con.execute("SET lock_configuration = true")


def is_select(statement: str) -> bool:
    """Whether ``statement`` is exactly one read-only query (SELECT, WITH, FROM, VALUES, SHOW, …),
    as DuckDB's own parser reads it; a parse error raises ``duckdb.Error``."""
    parsed = duckdb.extract_statements(statement)
    return len(parsed) == 1 and parsed[0].type == duckdb.StatementType.SELECT



def _sql_str(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"
