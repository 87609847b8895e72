"""A dict spec written as TOML text, in time linear in its size.

The runs table records the text a spec was loaded from; a dict's is written here. tomlkit wrote it
before, and tomlkit re-indexes an array on every append: a list of 10,000 values took seconds and
one of 100,000 never finished, before the spec could be refused for its size. This writer lays
out a spec as tomlkit did (plain keys first, then tables; a table holding only tables gets no
header of its own; arrays of tables as ``[[name]]``), so a spec's recorded text, and the identity
digested from it, are what they were.
"""

from __future__ import annotations

import math
import re
from typing import Any, Mapping

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")
_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def toml_text(doc: Mapping[str, Any]) -> str:
    """``doc`` (strings, numbers, booleans, lists and dicts) as TOML text.

    Raises:
        TypeError: for a value TOML has no type for (None, an object): the caller says it otherwise.
    """
    lines: list[str] = []
    _table(doc, (), lines, aot=False)
    return "".join(f"{line}\n" for line in lines)


def _table(table: Mapping[str, Any], path: tuple[str, ...], lines: list[str], *, aot: bool) -> None:
    """Append ``table``'s lines: its header (unless at the top, or a table of tables only), its
    plain keys, then its tables and arrays of tables.

    Blank lines fall where tomlkit put them, which follows the dict's order: one before a table or
    an array of tables that is not its table's first key, and one between two tables of an array
    when the first is not empty."""
    plain = [(k, v) for k, v in table.items() if not _is_table(v) and not _is_tables(v)]
    if path and (aot or plain or len(plain) == len(table)):
        name = ".".join(_key(k) for k in path)
        lines.append(f"[[{name}]]" if aot else f"[{name}]")
    lines.extend(f"{_key(k)} = {_value(v)}" for k, v in plain)
    for index, (key, value) in enumerate(table.items()):
        if _is_table(value):
            if index > 0 or (lines and (not path or _after_key(lines))):
                lines.append("")
            _table(value, (*path, key), lines, aot=False)
        elif _is_tables(value):
            for i, item in enumerate(value):
                if (index > 0) if i == 0 else bool(value[i - 1]):
                    lines.append("")
                _table(item, (*path, key), lines, aot=True)


def _after_key(lines: list[str]) -> bool:
    """Whether the last line is a key's (not a header, not blank)."""
    return bool(lines[-1]) and not lines[-1].startswith("[")


def _is_table(value: Any) -> bool:
    return isinstance(value, Mapping)


def _is_tables(value: Any) -> bool:
    """Whether ``value`` is written as an array of tables: a non-empty list of dicts only."""
    return isinstance(value, list) and bool(value) and all(isinstance(v, Mapping) for v in value)


def _key(key: str) -> str:
    return key if _BARE_KEY.fullmatch(key) else _string(key)


def _value(value: Any, within_table: bool = False) -> str:
    """One value inline: a list as ``[a, b]``, a dict as ``{k = v}`` (``{k = v,l = w}`` within
    another, as tomlkit wrote it)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)  # inf, -inf, nan as TOML writes them
    if isinstance(value, str):
        return _string(value)
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, Mapping):
        separator = "," if within_table else ", "
        return "{" + separator.join(f"{_key(k)} = {_value(v, True)}" for k, v in value.items()) + "}"
    raise TypeError(f"TOML has no type for {type(value).__name__}")


def _string(text: str) -> str:
    """``text`` as a TOML basic string: quotes, backslashes and control characters escaped."""
    out = []
    for c in text:
        if c in _ESCAPES:
            out.append(_ESCAPES[c])
        elif ord(c) < 0x20 or ord(c) == 0x7F:
            out.append(f"\\u{ord(c):04x}")
        else:
            out.append(c)
    return '"' + "".join(out) + '"'
