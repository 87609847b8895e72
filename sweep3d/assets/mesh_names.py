"""The object and material names Blender will give a mesh file's contents, read without Blender.

A spec picks parts of a file by name (``parts = ["orange_Cube"]``) and overrides materials by
name, so a typo should fail at load with "did you mean", not after workers start. The names are
those Blender 4.5's importers give (checked by importing test files with bpy):

- OBJ: one object per ``o`` line that has faces, named by the rest of the line; faces before the
  first ``o`` (or in a file without one) make an object named after the file. ``g`` groups do not
  split objects (the importer's ``use_split_groups`` is off). A repeated name gets Blender's
  ``.001``, ``.002``. Materials are named by ``usemtl``.
- glTF/GLB: one object per node, named by the node, else by its mesh (else ``Mesh_<index>``),
  else ``Node_<index>``. Materials by their name, else ``Material_<index>``.

Other formats (PLY, STL) return None: their names are checked when a worker imports them.
"""

from __future__ import annotations

import json
import re
import struct
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

#: Blender's longest ID name, in bytes (longer names are cut).
MAX_NAME_BYTES = 63

_OBJ_LINE = re.compile(rb"(?m)^[ \t]*(o|usemtl|f)(?:[ \t]+([^\r\n]*))?[ \t]*\r?$")


@dataclass
class FileNames:
    """A mesh file's objects in Blender's order of names, each with the materials its faces use
    and its children (glTF nodes; OBJ objects have none)."""

    materials: dict[str, set[str]] = field(default_factory=dict)  # object -> material names
    children: dict[str, list[str]] = field(default_factory=dict)

    @property
    def objects(self) -> list[str]:
        return list(self.materials)

    def selected(self, parts: list[str] | None) -> list[str]:
        """The objects ``parts`` render: each named one and its descendants (all without ``parts``)."""
        if not parts:
            return self.objects
        out: dict[str, None] = {}
        todo = list(parts)
        while todo:
            name = todo.pop()
            if name not in out:
                out[name] = None
                todo += self.children.get(name, [])
        return [name for name in self.objects if name in out]

    def materials_of(self, objects: list[str]) -> list[str]:
        return sorted({m for o in objects for m in self.materials.get(o, ())})


def file_names(data: bytes, filename: str) -> FileNames | None:
    """The names in a mesh file's bytes (``filename`` gives the format and OBJ's default object);
    None for a format whose names only Blender knows."""
    suffix = Path(filename).suffix.lower()
    if suffix == ".obj":
        return _obj(data, Path(filename).stem)
    if suffix == ".gltf":
        return _gltf(json.loads(data))
    if suffix == ".glb":
        return _gltf(_glb_json(data))
    return None


def read_mesh_bytes(ref: str) -> bytes:
    """The bytes of a resolved mesh reference (a path, or ``archive.zip#member``)."""
    archive, sep, member = ref.partition("#")
    if sep:
        with zipfile.ZipFile(archive) as zf:
            return zf.read(member)
    return Path(archive).read_bytes()


def _unique(names: list[str]) -> list[str]:
    """Blender's names for objects asked to be called ``names``: cut to 63 bytes, repeats suffixed."""
    out: list[str] = []
    taken: set[str] = set()
    for name in names:
        name = name.encode()[:MAX_NAME_BYTES].decode(errors="ignore")
        base, n = name, 0
        while name in taken:
            n += 1
            name = f"{base[: MAX_NAME_BYTES - 4]}.{n:03d}"
        taken.add(name)
        out.append(name)
    return out


def _obj(data: bytes, stem: str) -> FileNames:
    asked: list[str] = []  # one per object with faces, in file order
    used: list[set[str]] = []
    current, has_faces, material = stem, False, None
    current_used: set[str] = set()

    def close() -> None:
        if has_faces:
            asked.append(current)
            used.append(current_used)

    for match in _OBJ_LINE.finditer(data):
        keyword, rest = match.group(1), (match.group(2) or b"").decode("utf-8", errors="replace").strip()
        if keyword == b"o" and rest:
            close()
            current, has_faces, current_used = rest, False, set()
        elif keyword == b"usemtl" and rest:
            material = rest
        elif keyword == b"f":
            has_faces = True
            if material is not None:
                current_used.add(material)
    close()
    names = _unique(asked)
    return FileNames(dict(zip(names, used)))


def _gltf(doc: dict) -> FileNames:
    meshes = doc.get("meshes") or []
    materials = doc.get("materials") or []
    nodes = doc.get("nodes") or []
    asked, used = [], []
    for i, node in enumerate(nodes):
        mesh_index = node.get("mesh")
        mesh = meshes[mesh_index] if isinstance(mesh_index, int) and 0 <= mesh_index < len(meshes) else None
        fallback = f"Node_{i}" if mesh is None else (mesh.get("name") or f"Mesh_{mesh_index}")
        name = node.get("name") or fallback
        asked.append(name)
        used.append({materials[p["material"]].get("name") or f"Material_{p['material']}"
                     for p in (mesh or {}).get("primitives", [])
                     if isinstance(p.get("material"), int) and 0 <= p["material"] < len(materials)})
    names = _unique(asked)
    children = {names[i]: [names[c] for c in node.get("children", []) if isinstance(c, int) and 0 <= c < len(names)]
                for i, node in enumerate(nodes)}
    return FileNames(dict(zip(names, used)), children)


def _glb_json(data: bytes) -> dict:
    """The JSON chunk of a binary glTF (the first chunk, by the format's rule)."""
    length, kind = struct.unpack_from("<I4s", data, 12)
    if kind != b"JSON":
        raise ValueError("the first chunk of the .glb file is not its JSON")
    return json.loads(data[20 : 20 + length])
