"""The materials Blender will render for each object of a spec, read from a real import.

What an importer makes of a file is not what the file says: Blender 4.5's OBJ importer turns an
MTL's ``d`` into the Principled BSDF's Alpha, the mean of ``Tf`` into Transmission Weight, ``Pc``
into a quarter of it as Coat Weight, and ``illum`` 3 to 7 into Metallic 1. The only faithful
account is Blender's own, so this imports each object (with its parts and overrides, as a render
worker does) in a child process (:mod:`.child`): the caller's process never imports bpy.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

from sweep3d.stages.render.child import call_in_child
from sweep3d.stages.render.worker_protocol import Look

#: What a row holds per material, beside ``part``, ``material`` and ``overridden``.
COLUMNS = ("base_color", "opacity", "roughness", "metallic", "transmission", "ior", "coat")


def describe_materials(items: list[tuple[str, Look | None]]) -> list[list[dict[str, Any]] | str]:
    """Per ``(mesh path, look)``: one row per rendered part and material (see
    ``looks.effective_materials``), or the user error its import gave, as text."""
    if not items:
        return []
    return call_in_child(_describe_in_this_process, items)


def _describe_in_this_process(items: list[tuple[str, Look | None]]) -> list[list[dict[str, Any]] | str]:
    os.dup2(os.open(os.devnull, os.O_WRONLY), 1)  # Blender prints progress straight to fd 1
    from sweep3d.core import UserError
    from sweep3d.stages.render.cycles.blender_looks import effective_materials
    from sweep3d.stages.render.cycles.scene import BlenderScene
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderSettings

    out: list[list[dict[str, Any]] | str] = []
    with tempfile.TemporaryDirectory(prefix="sweep3d-materials-") as scratch:
        scene = BlenderScene(RenderSettings(resolution=8, samples=1, denoise=False), Path(scratch))
        for mesh, look in items:
            try:
                scene.prepare(mesh, EnvironmentRef(color=(1.0, 1.0, 1.0)), look)
            except UserError as exc:
                out.append(str(exc))
                continue
            loaded = scene.objects.get((mesh, look))
            out.append(effective_materials(loaded.meshes, loaded.names, look))
    return out
