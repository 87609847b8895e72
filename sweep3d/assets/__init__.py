"""What is read from mesh and HDRI files without Blender: where assets come from and their
digests, the names a mesh holds, and the cheap checks a file passes before Blender sees it."""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used. From outside, import through here.
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

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
