"""Check an object's ``parts`` and ``materials`` names against its mesh file when the spec loads.

Names are read without Blender (:mod:`sweep3d.assets.mesh_names`) for OBJ and glTF; a typo is one line
with "did you mean" and the file's names. Other formats are checked by the render worker that
imports them (``stages/render/cycles/blender_looks.py``), with the same wording.
"""

from __future__ import annotations

import difflib
from types import UnionType
from typing import Any, Callable, Union, get_args, get_origin

from pydantic import BaseModel

from sweep3d.assets import file_names, read_mesh_bytes
from sweep3d.core import SpecError
from sweep3d.spec.models import ObjectSpec

#: Names listed in a message before "…".
SHOWN = 12


def unknown_name(kind: str, name: str, valid: list[str], where: str) -> str:
    """The problem text for a name the file lacks: did-you-mean, then the names it has."""
    close = difflib.get_close_matches(name, valid, n=1, cutoff=0.5)
    if not close:
        close = [v for v in valid if v.lower() == name.lower()][:1]
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    listed = ", ".join(repr(v) for v in valid[:SHOWN]) + (f", … ({len(valid)} in all)" if len(valid) > SHOWN else "")
    return f"no {kind} {name!r} in {where}{hint}; its {kind}s: {listed or '(none)'}"


def check_look(obj: ObjectSpec, ref: str, index: int, fail: Callable[[str, str], SpecError]) -> None:
    """Refuse ``parts`` or ``materials`` names that ``ref``'s file does not have.

    Raises:
        SpecError: naming ``objects[index].parts[j]`` or ``objects[index].materials.NAME``.
    """
    if not obj.parts and not obj.materials:
        return
    where = ref.partition("#")[2] or ref
    try:
        names = file_names(read_mesh_bytes(ref), where)
    except (OSError, ValueError, KeyError):
        return  # the file's own checks (sniff) speak for an unreadable file; Blender has the last word
    if names is None:
        return
    short = where.rsplit("/", 1)[-1]
    for j, part in enumerate(obj.parts or []):
        if part not in names.materials:
            raise fail(f"objects[{index}].parts[{j}]", unknown_name("object", part, names.objects, short)
                       + "; give the names of objects in the file (sweep3d plan --materials lists them)")
    rendered = names.materials_of(names.selected(obj.parts))
    for material in obj.materials:
        if material not in rendered:
            what = f"the rendered parts of {short}" if obj.parts else short
            raise fail(f"objects[{index}].materials.{material}", unknown_name("material", material, rendered, what)
                       + "; name a material of the rendered parts, or use material = {...} for all of them")


def valid_keys(model: type[BaseModel], loc: tuple) -> list[str]:
    """The keys the table at ``loc`` (a pydantic error's location, without the key) accepts, for
    "did you mean"; empty where the path leaves the spec's models."""
    annotation: Any = model
    for part in loc:
        annotation = _unwrap(annotation, keyed=False)
        if _is_model(annotation):
            if not isinstance(part, str) or part not in annotation.model_fields:
                return []
            annotation = annotation.model_fields[part].annotation
        else:  # an index into a list or a key of a dict
            inner = _unwrap(annotation, keyed=True)
            if inner is annotation:
                return []
            annotation = inner
    annotation = _unwrap(annotation, keyed=False)
    return list(annotation.model_fields) if _is_model(annotation) else []


def _is_model(annotation: Any) -> bool:
    return isinstance(annotation, type) and issubclass(annotation, BaseModel)


def _unwrap(annotation: Any, keyed: bool) -> Any:
    """``X | None`` → X; with ``keyed`` (the path indexes a list or a dict) also ``list[X]``,
    ``dict[str, X]`` → X."""
    while True:
        args = [a for a in get_args(annotation) if a is not type(None)]
        origin = get_origin(annotation)
        if origin in (Union, UnionType) and len(args) == 1:
            annotation = args[0]
        elif keyed and origin in (list, dict) and args:
            annotation, keyed = args[-1], False
        else:
            return annotation
