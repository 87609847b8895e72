"""A spec's ``include``: shared tables (objects, environments, controls, …) read from other files.

    include = ["household.toml"]          # relative to the spec; one list of objects, many studies

Lists of tables (``objects``, ``environments``, ``controls``, ``models``) are joined: an
included file's entries first, in include order, then the spec's own. Tables (``[render]``,
``[policy]``, …) are merged key by key, the including file's keys winning. An included file
may include others; a file included twice, or a cycle, is an error. Relative paths in an
included file (meshes, HDRIs, the store, a design table, a control's files) are relative to
*that* file, as they would be if it were a spec of its own.

An error in an included entry names the file it comes from and its index there.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sweep3d.assets import not_a_file
from sweep3d.core import SpecError

LISTS = ("objects", "environments", "controls", "models")
TABLES = ("experiment", "render", "model", "evaluator", "policy", "postprocess", "report", "aggregate", "stability")
#: A control entry's folder when it came from an included file (its file parameters resolve there).
BASE_KEY = "__folder__"


@dataclass
class Included:
    """The spec with its includes merged in, the texts it was made of, and where each list entry came from."""

    raw: dict[str, Any]
    texts: list[tuple[str, str]] = field(default_factory=list)  # (file, text) of each included file
    origins: dict[str, list[tuple[str, int]]] = field(default_factory=dict)  # list key → (file, index) per entry
    keys: dict[str, str] = field(default_factory=dict)  # "table.key" → the file it came from

    @property
    def folders(self) -> list[Path]:
        """The folders of the included files (a plug-in module beside one is importable)."""
        return list(dict.fromkeys(Path(file).parent for file, _ in self.texts))


def merge_includes(raw: dict[str, Any], file: str, base: Path) -> Included:
    """``raw`` with its ``include`` resolved (``file`` and ``base``: the spec's name and folder).

    Raises:
        SpecError: an ``include`` that is not a path or list of paths, a file that cannot be read
            or parsed, a file included twice or in a cycle, an ``include`` key of another type.
    """
    return _merge(raw, file, base, (str(Path(file).resolve()) if Path(file).exists() else file,), [])


def _merge(raw: dict[str, Any], file: str, base: Path, chain: tuple[str, ...], texts: list[tuple[str, str]]) -> Included:
    from sweep3d.spec.loader import parse_toml

    own = dict(raw)
    names = own.pop("include", [])
    if isinstance(names, str):
        names = [names]
    if not (isinstance(names, list) and all(isinstance(n, str) and n for n in names)):
        raise SpecError(file, "include", 'must be a path or a list of paths to TOML files, e.g. ["shared.toml"]')
    merged: dict[str, Any] = {}
    origins: dict[str, list[tuple[str, int]]] = {}
    keys: dict[str, str] = {}
    for name in names:
        path = (base / Path(name).expanduser()).resolve()
        if str(path) in chain:
            raise SpecError(file, "include", f"{name!r} includes itself (through {' → '.join(Path(c).name for c in chain)})")
        if any(str(path) == seen for seen, _ in texts):
            raise SpecError(file, "include", f"{name!r} is included twice; include it once")
        kind = not_a_file(path)
        if kind is not None and kind != "a directory":  # a FIFO's read would wait for a writer for ever
            raise SpecError(file, "include", f"{name!r} is {kind}, not a TOML file; include a file")
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise SpecError(file, "include", f"cannot read {name!r} ({getattr(exc, 'strerror', None) or exc}); "
                                             "paths are relative to the including file") from None
        texts.append((str(path), text))
        raw_inner = parse_toml(text, str(path))
        for key in LISTS:  # a list the spec also has would hide a malformed one here: say so now
            if key in raw_inner and not _tables(raw_inner, key):
                raise SpecError(str(path), key, f"must be an array of tables, written [[{key}]]")
        inner = _merge(_rebased(raw_inner, path.parent), str(path), path.parent, (*chain, str(path)), texts)
        _join(merged, origins, keys, inner.raw, inner.origins, inner.keys)
    for key in LISTS:
        if key in own and not isinstance(own[key], list):
            return Included({**merged, **own}, texts, origins, keys)  # the spec's validation names the mistake
    mine = {f"{table}.{key}": file for table in TABLES if isinstance(own.get(table), dict) for key in own[table]}
    _join(merged, origins, keys, own, {key: [(file, i) for i in range(len(own.get(key, [])))] for key in LISTS}, mine)
    return Included(merged, texts, origins, keys)


#: A table whose other keys belong to what this key picks: a different pick replaces the table whole.
PICKS = {"policy": "type", "evaluator": "kind", "model": "name"}


def _join(into: dict[str, Any], origins: dict[str, list[tuple[str, int]]], keys: dict[str, str],
          raw: dict[str, Any], where: dict[str, list[tuple[str, int]]], whose: dict[str, str]) -> None:
    """Add ``raw``'s tables to ``into``: lists appended, tables merged (``raw``'s keys win; a table
    that picks another policy, evaluator or model replaces the included one whole)."""
    for key, value in raw.items():
        if key in LISTS and isinstance(value, list) and isinstance(into.get(key, []), list):
            into[key] = [*into.get(key, []), *value]
            origins[key] = [*origins.get(key, []), *where.get(key, [])]
        elif key in TABLES and isinstance(value, dict) and isinstance(into.get(key), dict):
            pick = PICKS.get(key)
            if pick in value and value[pick] != into[key].get(pick):
                for name in [k for k in keys if k.startswith(f"{key}.")]:
                    del keys[name]
                into[key] = dict(value)
            else:
                into[key] = {**into[key], **value}
        else:
            into[key] = value
    keys.update(whose)


def _rebased(raw: dict[str, Any], folder: Path) -> dict[str, Any]:
    """An included file's relative paths made absolute against its own folder."""
    out = dict(raw)
    out["objects"] = [_with_path(o, "mesh", folder) for o in raw.get("objects", [])] if _tables(raw, "objects") else \
        raw.get("objects")
    out["environments"] = [_with_path(e, "hdri", folder) for e in raw.get("environments", [])] \
        if _tables(raw, "environments") else raw.get("environments")
    if _tables(raw, "controls"):
        out["controls"] = [{**c, BASE_KEY: str(folder)} for c in raw.get("controls", [])]
    for table, key in (("experiment", "store"), ("policy", "file")):
        if isinstance(raw.get(table), dict):
            out[table] = _with_path(raw[table], key, folder)
    return {k: v for k, v in out.items() if v is not None or k in raw}


def _tables(raw: dict[str, Any], key: str) -> bool:
    return isinstance(raw.get(key), list) and all(isinstance(t, dict) for t in raw[key])


def _with_path(table: dict[str, Any], key: str, folder: Path) -> dict[str, Any]:
    """``table`` with ``table[key]`` (a path, maybe ``archive.zip#member``) relative to ``folder``."""
    value = table.get(key)
    if not isinstance(value, str) or not value or value.startswith("builtin:"):
        return table
    head, sep, member = value.partition("#")
    path = Path(head).expanduser()
    return table if path.is_absolute() else {**table, key: f"{folder / path}{sep}{member}"}


_ENTRY = re.compile(r"^(objects|environments|controls|models)\[(\d+)\](.*)$")


def located(error: SpecError, included: Included) -> SpecError:
    """``error`` naming the file an entry or a table's key came from, and the entry's index in
    that file (the spec's own entries come after the included ones in the merged lists)."""
    if not included.texts:
        return error
    match = _ENTRY.match(error.key)
    if match:
        key, index, rest = match.group(1), int(match.group(2)), match.group(3)
        entries = included.origins.get(key, [])
        if index >= len(entries):
            return error
        file, local = entries[index]
        return SpecError(file, f"{key}[{local}]{rest}", error.problem)
    table_key = ".".join(error.key.split(".")[:2])
    file = included.keys.get(table_key)
    return SpecError(file, error.key, error.problem) if file and file != error.file else error
