"""What is read from mesh and HDRI files without Blender: where assets come from and their
digests, the names a mesh holds, and the cheap checks a file passes before Blender sees it."""

from __future__ import annotations

__all__ = [
    "MITSUBA_FORMATS", "blender_version", "bpy_root", "check_archive", "check_file", "check_hdri", "check_materials", "check_mesh",
    "file_names", "materialise_mesh", "mesh_digest", "mesh_files", "not_a_file", "read_mesh_bytes", "resolve_hdri",
    "resolve_mesh", "unreadable"
]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles; from outside the package, import through here.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.assets.materials import check_materials
    from sweep3d.assets.mesh_names import file_names, read_mesh_bytes
    from sweep3d.assets.sniff import check_file, check_hdri, check_mesh, not_a_file, unreadable
    from sweep3d.assets.sources import (
        blender_version,
        bpy_root,
        check_archive,
        materialise_mesh,
        mesh_digest,
        mesh_files,
        resolve_hdri,
        resolve_mesh,
    )
    from sweep3d.assets.texture_images import MITSUBA_FORMATS

__getattr__, __dir__ = _exports(__name__, {
    "blender_version": ("sweep3d.assets.sources", "blender_version"),
    "bpy_root": ("sweep3d.assets.sources", "bpy_root"),
    "check_archive": ("sweep3d.assets.sources", "check_archive"),
    "check_file": ("sweep3d.assets.sniff", "check_file"),
    "check_hdri": ("sweep3d.assets.sniff", "check_hdri"),
    "check_materials": ("sweep3d.assets.materials", "check_materials"),
    "MITSUBA_FORMATS": ("sweep3d.assets.texture_images", "MITSUBA_FORMATS"),
    "check_mesh": ("sweep3d.assets.sniff", "check_mesh"),
    "file_names": ("sweep3d.assets.mesh_names", "file_names"),
    "materialise_mesh": ("sweep3d.assets.sources", "materialise_mesh"),
    "mesh_digest": ("sweep3d.assets.sources", "mesh_digest"),
    "mesh_files": ("sweep3d.assets.sources", "mesh_files"),
    "not_a_file": ("sweep3d.assets.sniff", "not_a_file"),
    "read_mesh_bytes": ("sweep3d.assets.mesh_names", "read_mesh_bytes"),
    "resolve_hdri": ("sweep3d.assets.sources", "resolve_hdri"),
    "resolve_mesh": ("sweep3d.assets.sources", "resolve_mesh"),
    "unreadable": ("sweep3d.assets.sniff", "unreadable"),
})
