"""Run a control's scene edit so that nothing it does outlives its job.

A rendered control may define ``edit(scene, params)``: it gets the live Blender scene, posed for
the job, and may add or change anything. The worker does not trust it to clean up. Before the
edit it notes every datablock that exists and a fingerprint of each (the values of its writable
properties, its node trees' nodes, sockets and links, its meshes' geometry); after the render it
removes every datablock the edit made, and fingerprints the rest again. Datablocks the edit only
*added* are gone; if it changed one that was there before (a material of the mesh, a render
setting), the worker cannot know how to undo that change, so it rebuilds its Blender scene from
nothing before the next job: slow (every mesh and world is loaded again), but never wrong. The
render stage then tells the user, once, which control did that and how to avoid it.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any

#: The ``bpy.data`` collections whose datablocks can change what a render shows.
COLLECTIONS = ("objects", "meshes", "curves", "materials", "node_groups", "worlds", "lights", "cameras",
               "images", "textures", "scenes", "collections", "volumes", "pointclouds", "hair_curves",
               "grease_pencils", "lattices", "metaballs", "particles", "fonts", "movieclips", "masks")

#: Properties that say nothing of what renders, change on their own, or are too big to read per job.
SKIPPED = frozenset({
    "rna_type", "bl_rna", "id_data", "original", "is_evaluated", "users", "session_uid", "is_runtime_data",
    "tag", "preview", "tool_settings", "pixels", "is_editmode", "is_dirty", "bindcode",
    "wireframe_color_type",  # reads print enum warnings
    "uv_layer_stencil", "uv_layer_clone",  # texture-paint UI state, and slow to read (10 ms each)
    "file_format",  # an image's: slow to read, and only how it would be saved
    "select", "hide_select", "active_material_index", "active_index",  # selection and UI state
})
#: What of a scene can change a render (the rest is tool, timeline and UI state that operators such
#: as ``primitive_cylinder_add`` move: the 3D cursor, the active object, keying sets).
SCENE = ("render", "cycles", "view_settings", "display_settings", "sequencer_colorspace_settings", "world",
         "camera", "collection", "view_layers", "node_tree", "use_nodes", "frame_current", "unit_settings", "cycles_curves")
#: What of a view layer can change a render (not its active object or layer collection).
VIEW_LAYER = ("use", "samples", "use_pass_z", "use_pass_object_index", "use_pass_material_index", "use_pass_uv",
              "use_pass_normal", "use_pass_mist", "use_pass_combined", "cycles", "material_override",
              "use_freestyle", "use_solid", "use_sky", "use_volumes", "use_motion_blur")
#: Mesh element collections: fingerprinted from their arrays (:func:`_geometry`), not item by item.
MESH_ELEMENTS = frozenset({
    "vertices", "edges", "polygons", "loops", "loop_triangles", "loop_triangle_polygons", "attributes",
    "uv_layers", "vertex_colors", "color_attributes", "polygon_normals", "vertex_normals", "corner_normals",
    "vertex_creases", "edge_creases", "skin_vertices", "vertex_paint_mask", "normals_domain",
})
MAX_DEPTH = 4  # nested structs followed from a datablock (node trees are walked apart, see _tree)
MAX_ITEMS = 4096  # a longer collection is fingerprinted by its length only


@dataclass(frozen=True)
class Snapshot:
    """The datablocks that existed before an edit, by pointer, with their fingerprints."""

    fingerprints: dict[int, str]


@dataclass(frozen=True)
class Aftermath:
    """What an edit left behind once its new datablocks are removed.

    Attributes:
        changed: the names of datablocks that existed before and differ after (``"Material 'mug'"``);
            empty when the edit only added things.
    """

    changed: tuple[str, ...]


def snapshot(bpy) -> Snapshot:
    """Every datablock's fingerprint, taken before an edit."""
    return Snapshot({id_.as_pointer(): fingerprint(bpy, id_) for id_ in _datablocks(bpy)})


def clean_up(bpy, before: Snapshot) -> Aftermath:
    """Remove every datablock made since ``before``, and name those that were there and changed."""
    made = [id_ for id_ in _datablocks(bpy) if id_.as_pointer() not in before.fingerprints]
    if made:
        bpy.data.batch_remove(made)
    changed = []
    for id_ in _datablocks(bpy):
        old = before.fingerprints.get(id_.as_pointer())
        if old is not None and fingerprint(bpy, id_) != old:
            changed.append(f"{type(id_).__name__} {id_.name!r}")
    removed = len(before.fingerprints) - sum(1 for id_ in _datablocks(bpy) if id_.as_pointer() in before.fingerprints)
    if removed:
        changed.append(f"{removed} datablock{'s' if removed > 1 else ''} removed")
    return Aftermath(tuple(changed))


def _datablocks(bpy) -> list[Any]:
    out = []
    for name in COLLECTIONS:
        out.extend(getattr(bpy.data, name, ()))
    return out


def fingerprint(bpy, datablock: Any) -> str:
    """A digest of what of ``datablock`` can change a render: its writable values, nested settings,
    node trees and geometry, with other datablocks it points to named by pointer."""
    out: list[Any] = []
    _walk(bpy, datablock, out, 0)
    if isinstance(datablock, bpy.types.Mesh):
        out.append(_geometry(datablock))
    return hashlib.blake2b(repr(out).encode(), digest_size=16).hexdigest()


def _walk(bpy, struct: Any, out: list[Any], depth: int) -> None:
    if isinstance(struct, bpy.types.NodeTree):
        _tree(bpy, struct, out, depth)
        return
    is_mesh = isinstance(struct, bpy.types.Mesh)
    only = SCENE if isinstance(struct, bpy.types.Scene) else VIEW_LAYER if isinstance(struct, bpy.types.ViewLayer) else None
    for prop in struct.bl_rna.properties:
        ident = prop.identifier
        if ident in SKIPPED or (is_mesh and ident in MESH_ELEMENTS) or (only is not None and ident not in only):
            continue
        try:
            value = getattr(struct, ident)
        except Exception:  # noqa: BLE001  (a property that cannot be read in this context)
            continue
        kind = prop.type
        if kind == "POINTER":
            _pointer(bpy, value, out, depth)
        elif kind == "COLLECTION":
            out.append((ident, len(value)))
            if len(value) <= MAX_ITEMS and depth < MAX_DEPTH:
                for item in value:
                    _pointer(bpy, item, out, depth)
        elif not prop.is_readonly:
            out.append((ident, tuple(value) if hasattr(value, "__len__") and not isinstance(value, str) else value))


def _pointer(bpy, value: Any, out: list[Any], depth: int) -> None:
    if value is None:
        out.append(None)
    elif isinstance(value, bpy.types.ID) and not value.is_embedded_data:
        out.append(value.as_pointer())  # another datablock: fingerprinted on its own
    elif depth < MAX_DEPTH:
        _walk(bpy, value, out, depth + 1)


def _tree(bpy, tree: Any, out: list[Any], depth: int) -> None:
    """A node tree as its nodes (settings and socket values) and links, without following the
    back-pointers between nodes, sockets and links."""
    for node in tree.nodes:
        out.append(("node", node.bl_idname, node.name))
        for prop in node.bl_rna.properties:
            ident = prop.identifier
            if ident in SKIPPED or ident in ("inputs", "outputs", "internal_links", "parent", "type"):
                continue
            value = getattr(node, ident, None)
            if prop.type == "POINTER":
                if isinstance(value, bpy.types.ID) or value is None:
                    _pointer(bpy, value, out, depth)
                elif depth < MAX_DEPTH and not isinstance(value, (bpy.types.Node, bpy.types.NodeSocket)):
                    _walk(bpy, value, out, depth + 1)
            elif prop.type != "COLLECTION" and not prop.is_readonly:
                out.append((ident, tuple(value) if hasattr(value, "__len__") and not isinstance(value, str) else value))
        for socket in (*node.inputs, *node.outputs):
            value = getattr(socket, "default_value", None)
            if value is not None and hasattr(value, "__len__") and not isinstance(value, str):
                value = tuple(value)
            out.append((socket.identifier, socket.enabled, socket.hide, value if not isinstance(value, bpy.types.ID)
                        else value.as_pointer()))
    for link in tree.links:
        out.append(("link", link.from_node.name, link.from_socket.identifier, link.to_node.name,
                    link.to_socket.identifier, link.is_muted))
    for name in ("interface",):
        if hasattr(tree, name):
            out.append((name, len(getattr(tree, name).items_tree)))


def _geometry(mesh: Any) -> str:
    """A digest of a mesh's vertex positions, faces and attribute layout."""
    import numpy as np

    h = hashlib.blake2b(digest_size=16)
    for elements, field, dtype in ((mesh.vertices, "co", np.float32), (mesh.loops, "vertex_index", np.int32),
                                   (mesh.polygons, "loop_start", np.int32),
                                   (mesh.polygons, "material_index", np.int32)):
        values = np.empty(len(elements) * (3 if field == "co" else 1), dtype=dtype)
        elements.foreach_get(field, values)
        h.update(values.tobytes())
    h.update(repr([(a.name, a.domain, a.data_type) for a in mesh.attributes]).encode())
    return h.hexdigest()
