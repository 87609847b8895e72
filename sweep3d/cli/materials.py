"""``sweep3d plan --materials``: the Principled BSDF values each object's materials render with.

Read from a real import in a Blender child process (``stages/render/cycles/describe.py``), so the
importer's own mapping of the file (an MTL's ``d``, ``Tf``, ``Pc``, ``illum``) shows as rendered.
"""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.table import Column, Table

from sweep3d.assets import materialise_mesh
from sweep3d.spec import LoadedSpec
from sweep3d.stages.render import COLUMNS, Look, describe_materials, object_error

NOTE = ("values as Blender's importer set them from the file, * where the spec's material overrides them; "
        "linked: a texture or node drives it. Blender's OBJ importer: d → opacity, mean of Tf → transmission, "
        "Ni → ior, Pc × ¼ → coat, illum 3–7 → metallic 1")


def effective_materials(spec: LoadedSpec) -> list[list[dict[str, Any]]]:
    """Per object, one row per rendered part and material with its effective values.

    Raises:
        SpecError: an object's parts or overrides do not fit its file (found on import).
    """
    items = [(str(materialise_mesh(spec.meshes[o.name], spec.store)), Look.of(o)) for o in spec.objects]
    described = describe_materials(items)
    for obj, rows in zip(spec.objects, described):
        if isinstance(rows, str):
            raise object_error(spec, obj.name, rows)
    return described  # type: ignore[return-value]


def print_materials(console: Console, spec: LoadedSpec, described: list[list[dict[str, Any]]]) -> None:
    """One table per object: each rendered part's materials and their effective values."""
    for obj, rows in zip(spec.objects, described):
        table = Table(*(Column(name, overflow="fold") for name in ("part", "material", *COLUMNS)),
                      title=f"{escape(obj.name)}: {escape(obj.mesh)}", title_justify="left")  # wrapped, never cut
        for row in rows:
            table.add_row(escape(row["part"]), escape(row["material"]),
                          *(_cell(row[c], c in row["overridden"]) for c in COLUMNS))
        console.print(table)
    console.print(NOTE, style="dim")


def _cell(value: Any, overridden: bool) -> str:
    mark = "*" if overridden else ""
    if value is None:
        return "–"
    if isinstance(value, list):
        return "(" + ", ".join(exact(v) for v in value) + ")" + mark
    return (value if isinstance(value, str) else exact(value)) + mark


def exact(value: float) -> str:
    """The value Blender holds (a 32-bit float), in the fewest digits that give it back exactly:
    what a user copies into a spec (``0.8``, not ``0.800000011920929``, nor ``0.123`` for 0.12345679)."""
    import numpy as np

    return np.format_float_positional(np.float32(value), unique=True, trim="-")
