"""Spec values keep the type TOML gave them: a string is never read as a number or a boolean.

Pydantic's lax mode turns ``samples = "4"`` into 4, ``denoise = "yes"`` into True and
``workers = true`` into 1. TOML has types, so a quoted number is a mistake (often a sign the
value came from somewhere it should not have), and one worth a line. :class:`Typed` refuses those
coercions for every field before pydantic sees the value, while keeping what is exact: an int
where a float belongs (``strength = 2``, and Python dicts written by hand), a list where a tuple
belongs (TOML has no tuples). It is the base of the spec's models and of every plug-in's
``Params``. Names must also be printable: :func:`printable` refuses control characters.
"""

from __future__ import annotations

import types
import typing
import unicodedata
from typing import Any

from pydantic import BaseModel, ValidationInfo, field_validator

#: The scalar kinds a value may have, as TOML writes them.
_KINDS: dict[type, str] = {bool: "bool", int: "number", float: "number", str: "string"}
_SHOWN = {"bool": "a boolean (true or false)", "number": "a number", "string": "a string"}
#: The strings pydantic's lax mode reads as booleans.
LAX_BOOLS = {"0", "1", "f", "t", "n", "y", "no", "yes", "on", "off", "false", "true"}


def _kinds(annotation: Any) -> set[str] | None:
    """The scalar kinds ``annotation`` accepts; None when it accepts others too (a model, a path,
    ``Any``): then pydantic alone judges."""
    origin = typing.get_origin(annotation)
    if origin is typing.Annotated:
        return _kinds(typing.get_args(annotation)[0])
    if origin in (typing.Union, types.UnionType):
        found: set[str] = set()
        for arg in typing.get_args(annotation):
            if arg is type(None):
                continue
            kinds = _kinds(arg)
            if kinds is None:
                return None
            found |= kinds
        return found
    if origin is typing.Literal:
        return {_KINDS.get(type(v), "other") for v in typing.get_args(annotation)}
    return {_KINDS[annotation]} if annotation in _KINDS else None


def _items(annotation: Any, n: int) -> list[Any] | None:
    """The item annotations of a list or tuple annotation for ``n`` items; None for other types."""
    origin = typing.get_origin(annotation)
    if origin is typing.Annotated:
        return _items(typing.get_args(annotation)[0], n)
    if origin in (typing.Union, types.UnionType):
        found = [a for a in (_items(arg, n) for arg in typing.get_args(annotation)) if a is not None]
        return found[0] if len(found) == 1 else None
    args = typing.get_args(annotation)
    if origin in (list, set, frozenset) and len(args) == 1:
        return [args[0]] * n
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        return [args[0]] * n
    if origin is tuple and len(args) == n:
        return list(args)
    return None


def coercion(annotation: Any, value: Any) -> str | None:
    """Why ``value`` would only fit ``annotation`` by a change of type (``"4"`` for an int,
    ``true`` for a number, ``1`` for a bool), or None when it fits as it is (or pydantic decides)."""
    if isinstance(value, (list, tuple)):
        items = _items(annotation, len(value))
        problems = (coercion(a, v) for a, v in zip(items or (), value))
        return next((f"[{i}] {p}" for i, p in enumerate(problems) if p), None)
    kind = _KINDS.get(type(value))
    wanted = _kinds(annotation)
    if kind is None or wanted is None or kind in wanted:
        return None
    if kind == "string" and not any(_reads_as(value, k) for k in wanted):
        return None  # pydantic refuses it too, with its own message
    expected = " or ".join(_SHOWN[k] for k in sorted(wanted) if k in _SHOWN) or "another type"
    fix = "; write it without quotes" if kind == "string" and "number" in wanted else ""
    return f"must be {expected}, not {_toml(value)}{fix}"


def _reads_as(text: str, kind: str) -> bool:
    """Whether pydantic's lax mode would read ``text`` as a value of ``kind``."""
    if kind == "bool":
        return text.strip().lower() in LAX_BOOLS
    try:
        return kind == "number" and float(text) is not None
    except ValueError:
        return False


def _toml(value: Any) -> str:
    """``value`` as the spec writes it."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return f'the string "{value}"' if isinstance(value, str) else repr(value)


class Typed(BaseModel):
    """A model whose fields take values of their own type (see the module's docstring)."""

    @field_validator("*", mode="before")
    @classmethod
    def _no_coercion(cls, value: Any, info: ValidationInfo) -> Any:
        field = cls.model_fields.get(info.field_name or "")
        problem = coercion(field.annotation, value) if field is not None else None
        if problem:
            raise ValueError(problem)
        return value


def printable(name: str) -> str:
    """``name``, refused when it holds a control character (NUL, ESC, a newline, a tab): such a
    name breaks the one-line messages, the report and the tables that print it."""
    bad = next((c for c in name if unicodedata.category(c) == "Cc"), None)
    if bad is not None:
        raise ValueError(f"{name!r} holds the control character {bad!r}; use printable characters only")
    return name
