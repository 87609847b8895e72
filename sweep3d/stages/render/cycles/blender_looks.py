"""An object's look in Blender: which of a file's objects render, material overrides, smoothing.

Imported objects and materials are renamed to worker-unique names right after each import, with
the names the file gave them kept aside: a worker imports many files (and one file once per
look), and Blender would otherwise call a second ``orange_Cube`` ``orange_Cube.001``, so a part
or material name would match only in the first import.

Overrides are applied to *copies* of the imported materials, so two objects sharing a material
(or a hidden part using it) keep the file's values. An overridden input is unlinked from the
texture or node that drove it, so the value given is the value rendered.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import count
from typing import Any

from sweep3d.core import UserError
from sweep3d.spec import unknown_name
from sweep3d.stages.render.worker_protocol import Look

#: Spec name -> Principled BSDF input (Blender 4.x names).
INPUTS = {"base_color": "Base Color", "opacity": "Alpha", "roughness": "Roughness", "metallic": "Metallic",
          "transmission": "Transmission Weight", "ior": "IOR", "coat": "Coat Weight"}
_serial = count()


@dataclass
class FileNames:
    """What the file called the objects and materials an import made (by their bpy names now)."""

    objects: dict[str, str] = field(default_factory=dict)
    materials: dict[str, str] = field(default_factory=dict)

    def of(self, datablock: Any) -> str:
        """The file's name for an imported object or material (its bpy name for anything else)."""
        table = self.materials if datablock.bl_rna.identifier == "Material" else self.objects
        return table.get(datablock.name, datablock.name)


def rename_imported(objects: list[Any], materials: list[Any]) -> FileNames:
    """Give what one import made worker-unique names, remembering the file's.

    The objects' data (meshes, cameras, lights) are renamed too: the glTF importer names an
    unnamed node after its mesh, which would otherwise be ``bananaMesh.001`` in a second import.
    """
    names = FileNames()
    for table, items, prefix in ((names.objects, objects, "o"), (names.materials, materials, "m")):
        for item in items:
            own = item.name
            item.name = f"sweep3d_{prefix}{next(_serial)}"
            table[item.name] = own
    for data in {o.data for o in objects if o.data is not None}:
        data.name = f"sweep3d_d{next(_serial)}"
    return names


def select_parts(imported: list[Any], names: FileNames, parts: tuple[str, ...] | None, where: str) -> set[Any]:
    """The imported objects that render: the named ones and their descendants (all without parts).

    Raises:
        UserError: a part the file does not have, with "did you mean" over its objects' names.
    """
    if parts is None:
        return set(imported)
    by_name = {names.of(o): o for o in imported}
    chosen: set[Any] = set()
    for part in parts:
        if part not in by_name:
            raise UserError(unknown_name("object", part, sorted(by_name), where) + "; give one of its objects")
        chosen.add(by_name[part])
    return {o for o in imported if o in chosen or any(a in chosen for a in _ancestors(o))}


def _ancestors(obj: Any) -> list[Any]:
    out = []
    while obj.parent is not None:
        obj = obj.parent
        out.append(obj)
    return out


def apply_look(bpy: Any, meshes: list[Any], names: FileNames, look: Look, where: str) -> None:
    """Smooth and override the materials of the rendered ``meshes`` as ``look`` says.

    Raises:
        UserError: a material name the rendered parts do not use, or an override on a material
            without a Principled BSDF.
    """
    if look.auto_smooth is not None:
        smooth_by_angle(meshes, look.auto_smooth)
    if not look.material and not look.materials:
        return
    rendered = sorted({names.of(s.material) for o in meshes for s in o.material_slots if s.material is not None})
    for name, _ in look.materials:
        if name not in rendered:
            raise UserError(unknown_name("material", name, rendered, f"the rendered parts of {where}")
                            + "; name a material of the rendered parts, or use material = {...} for all of them")
    named = dict(look.materials)
    copies: dict[Any, Any] = {}
    for obj in meshes:
        if not obj.material_slots and look.material:
            obj.data.materials.append(None)  # no material: Blender's default Principled BSDF, overridden
        for slot in obj.material_slots:
            original = slot.material
            values = dict(look.material) | dict(named.get(names.of(original), ()) if original is not None else {})
            if not values:
                continue
            if original not in copies:
                copies[original] = _overridden(bpy, original, values, names, where)
            slot.material = copies[original]


def _overridden(bpy: Any, original: Any | None, values: dict[str, Any], names: FileNames, where: str) -> Any:
    """A copy of ``original`` (a new Principled material when None) with ``values`` set."""
    if original is None:
        material = bpy.data.materials.new("sweep3d_override")
        material.use_nodes = True
        file_name = "(none)"
    else:
        material = original.copy()
        file_name = names.of(original)
    names.materials[material.name] = file_name
    bsdfs = [n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED"] if material.use_nodes else []
    if not bsdfs:
        raise UserError(f"material {file_name!r} of {where} has no Principled BSDF, so material overrides cannot "
                        "apply to it; remove them for this object")
    for bsdf in bsdfs:
        set_inputs(material.node_tree, bsdf, values)
    return material


def set_inputs(tree: Any, bsdf: Any, values: dict[str, Any], inputs: dict[str, str] = INPUTS) -> None:
    """Set Principled BSDF inputs by spec name (``inputs``: name → socket), cutting the links that drove them."""
    for key, value in values.items():
        socket = bsdf.inputs[inputs[key]]
        for link in list(socket.links):
            tree.links.remove(link)
        socket.default_value = (*value, 1.0) if key == "base_color" else value


def smooth_by_angle(meshes: list[Any], degrees: float) -> None:
    """Shade smooth, keeping edges sharper than ``degrees`` sharp (Blender 4.1+'s data API for
    what was auto smooth); the file's custom normals go, or they would win over the smoothing."""
    for mesh in {o.data for o in meshes}:
        custom = mesh.attributes.get("custom_normal")
        if custom is not None:
            mesh.attributes.remove(custom)
        mesh.shade_smooth()
        mesh.set_sharp_from_angle(angle=math.radians(degrees))


def effective_materials(meshes: list[Any], names: FileNames, look: Look | None) -> list[dict[str, Any]]:
    """Per rendered part and material slot, the Principled BSDF values Cycles will use (the first
    such node of the material), an input driven by a node shown as "linked", and which inputs the
    spec overrode."""
    given = set(dict(look.material)) if look else set()
    named = dict(look.materials) if look else {}
    rows = []
    for obj in sorted(meshes, key=names.of):
        slots = [s.material for s in obj.material_slots] or [None]
        for material in slots:
            row: dict[str, Any] = {"part": names.of(obj), "material": names.of(material) if material else "(none)"}
            bsdf = next((n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None) \
                if material is not None and material.use_nodes else None
            for key, socket_name in INPUTS.items():
                socket = bsdf.inputs[socket_name] if bsdf is not None else None
                row[key] = None if socket is None else "linked" if socket.is_linked else _plain(socket.default_value)
            row["overridden"] = sorted(given | set(dict(named.get(row["material"], ()))))
            rows.append(row)
    return rows


def _plain(value: Any) -> Any:
    """A socket value as plain Python (colours without alpha), rounded as Blender stores it (float32)."""
    if hasattr(value, "__len__"):
        return [round(float(v), 4) for v in list(value)[:3]]
    return round(float(value), 4)

