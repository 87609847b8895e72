"""SQL text for names and values that come from data (column names, labels): always quoted, so
no name can end a string or an identifier early."""

from __future__ import annotations


def identifier(name: str) -> str:
    """``name`` as a DuckDB identifier, in double quotes (a double quote in it doubled)."""
    return '"' + name.replace('"', '""') + '"'


def literal(text: str) -> str:
    """``text`` as a DuckDB string literal, in single quotes (a single quote in it doubled)."""
    return "'" + text.replace("'", "''") + "'"
