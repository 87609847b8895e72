"""Specs that come from no file: a dict (a notebook's) or a TOML string, validated as a file is.

Errors name ``<dict>`` or ``<string>`` as the file. A dict may hold plug-in objects where a file
holds names (``{"type": Vignette}``): each becomes the ``module:Name`` the file would write, so
the cache keys are those of the same spec written as TOML, and controls and policies are handed
to the loader as they are (a class defined in a notebook cell needs no module file, unless it is a
rendered control: see :func:`~sweep3d.spec.loader.importable_by_name`).
"""

from __future__ import annotations

import dataclasses
import importlib
import json
from pathlib import Path
from typing import Any, Mapping

from sweep3d.core import Registry, SpecError, UserError
from sweep3d.spec.catalogue import Catalogue
from sweep3d.spec.loader import LoadedSpec, parse_toml, spec_from_file, validate_spec
from sweep3d.spec.toml_text import toml_text

DICT_FILE = "<dict>"
STRING_FILE = "<string>"


def read_spec(spec: str | Path | Mapping[str, Any], catalogue: Catalogue, base: str | Path | None = None) -> LoadedSpec:
    """The spec ``spec`` describes: a file's path, TOML text (a string holding a newline or
    starting with ``[``) or a dict, validated against ``catalogue``. The layer-clean step behind
    ``sweep3d.load`` (the one public loader), for a front end that hands its own catalogue.

    Args:
        base: the folder a dict's or a string's relative paths resolve against (default the
            working directory); a file's resolve against its own folder.
    """
    folder = Path(base) if base is not None else Path.cwd()
    if isinstance(spec, Mapping):
        return spec_from_dict(spec, catalogue, folder)
    if isinstance(spec, str) and ("\n" in spec or spec.lstrip().startswith("[")):
        return spec_from_toml(spec, catalogue, folder)
    if not isinstance(spec, (str, Path)):
        raise UserError(f"a spec is a path, TOML text or a dict, got {type(spec).__name__}")
    if base is not None:
        raise UserError(f"{spec}: base= is for a dict or TOML text; a spec file's paths are relative to its folder")
    return spec_from_file(spec, catalogue)


def spec_from_toml(text: str, catalogue: Catalogue, base: Path) -> LoadedSpec:
    """Load a spec written as a TOML string; relative paths resolve against ``base``."""
    raw = parse_toml(text, STRING_FILE)
    return validate_spec(raw, catalogue, path=Path(STRING_FILE), base=base.resolve(), source=text)


def spec_from_dict(raw: Mapping[str, Any], catalogue: Catalogue, base: Path) -> LoadedSpec:
    """Load a spec given as a dict (TOML's tables as dicts, arrays of tables as lists of dicts);
    relative paths resolve against ``base``."""
    if not isinstance(raw, Mapping):
        raise SpecError(DICT_FILE, "", f"a spec is a dict of tables, got {type(raw).__name__}")
    plugins: dict[str, dict[str, Any]] = {"control": {}, "policy": {}}
    plain = _plain(raw, "", plugins, frozenset())
    catalogue = dataclasses.replace(
        catalogue, controls=_with(catalogue.controls, plugins["control"]),
        policies=_with(catalogue.policies, plugins["policy"]))
    return validate_spec(plain, catalogue, path=Path(DICT_FILE), base=base.resolve(), source=_as_text(plain))


#: The keys of a dict spec that may hold a plug-in object, and the kind the loader resolves it as.
PLUGIN_KEYS = {("controls", "type"): "control", ("policy", "type"): "policy", ("model", "name"): "model",
               ("models", "name"): "model", ("evaluator", "kind"): "evaluator"}


def plugin_name(obj: Any) -> str:
    """The ``module:Name`` a spec file would name ``obj`` by."""
    return f"{obj.__module__}:{obj.__qualname__}"


#: How deep a dict spec may nest (a spec file's are a few levels deep): deeper is a mistake, not a
#: spec, and would end in Python's RecursionError.
MAX_DEPTH = 64


def _plain(value: Any, key: str, plugins: dict[str, dict[str, Any]], within: frozenset[int]) -> Any:
    """``value`` with TOML's types only: paths as strings, tuples as lists, plug-in objects as
    their names (controls and policies collected into ``plugins`` by kind). ``within``: the ids of
    the dicts and lists that hold it, so one that holds itself is a :class:`SpecError`."""
    if isinstance(value, (Mapping, list, tuple)):
        within = _enter(value, key, within)
    if isinstance(value, Mapping):
        out = {}
        for name, item in value.items():
            if not isinstance(name, str):
                raise SpecError(DICT_FILE, key, f"keys are strings, got {name!r}")
            where = f"{key}.{name}" if key else name
            kind = PLUGIN_KEYS.get((key.split("[")[0], name))
            out[name] = (_plugin(item, where, kind, plugins) if kind and callable(item)
                         else _plain(item, where, plugins, within))
        return out
    if isinstance(value, (list, tuple)):
        return [_plain(item, f"{key}[{i}]", plugins, within) for i, item in enumerate(value)]
    if isinstance(value, Path):
        return str(value)
    if _is_array(value):  # a notebook's np.linspace(0, 2, 3) or np.float64(0.5): plain lists and numbers
        return _plain(value.tolist(), key, plugins, within)
    return value


def _is_array(value: Any) -> bool:
    """Whether ``value`` is an array or an array's scalar (numpy's, a pandas Series, a tensor),
    told by its ``tolist()`` so that numpy need not be imported."""
    return not isinstance(value, (type, str, bytes)) and callable(getattr(value, "tolist", None))


def _enter(value: Any, key: str, within: frozenset[int]) -> frozenset[int]:
    """``within`` and ``value``; a dict or list already among them (it contains itself) or nested
    past :data:`MAX_DEPTH` is refused in one line, not a RecursionError."""
    if id(value) in within:
        raise SpecError(DICT_FILE, key, "holds itself (a dict or list that contains itself, as after d['x'] = d); "
                                        "a spec is a tree of tables: give that key its own value")
    if len(within) >= MAX_DEPTH:
        raise SpecError(DICT_FILE, key, f"nests more than {MAX_DEPTH} levels deep; a spec is a few tables deep")
    return within | {id(value)}


def _plugin(obj: Any, key: str, kind: str, plugins: dict[str, dict[str, Any]]) -> str:
    """The name ``obj`` goes by in the spec. Controls and policies are handed to the loader as
    they are; models and evaluators are imported by name when they are used, so they must be
    found there (a notebook's ``__main__`` is)."""
    name = plugin_name(obj)
    if kind in plugins:
        plugins[kind][name] = obj
        return name
    module, _, attr = name.partition(":")
    try:
        found = getattr(importlib.import_module(module), attr, None)
    except Exception:  # noqa: BLE001  (not importable: said below)
        found = None
    if found is not obj:
        raise SpecError(DICT_FILE, key, f"{kind} {obj.__qualname__} cannot be found by its name {name!r}: define "
                                        "it at the top level of a module or notebook cell, or give 'module:name'")
    return name


def _with(registry: Registry, extra: dict[str, Any]) -> Registry:
    """``registry`` and the plug-ins ``extra`` names (``registry`` itself when there are none)."""
    if not extra:
        return registry
    added: Registry = Registry(registry.kind)
    for name, obj in extra.items():
        added.register(name)(obj)
    return Registry.union(registry.kind, registry, added)


def _as_text(plain: dict[str, Any]) -> str:
    """The spec as a TOML file would say it (JSON where TOML cannot: a None value), in time
    linear in its size (see :mod:`sweep3d.spec.toml_text`)."""
    try:
        return toml_text(plain)
    except TypeError:  # a value TOML has no type for: the validator says which
        return json.dumps(plain, default=str, indent=1)
