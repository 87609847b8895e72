"""The compositor's file output that extra render passes are read back through (runs in render workers)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence


def pass_outputs(scene: Any, folder: Path, slots: Sequence[str], exr: bool) -> tuple[Any, Any, Any]:
    """Turn on compositing and add a file output writing one greyscale file per slot to ``folder``
    (``<slot>_<frame>``) on every render, as data: no display transform.

    Args:
        exr: 32-bit float OpenEXR (ZIP) for values such as depth and object indices; else
            16-bit uncompressed PNG.
    Returns:
        The node tree, its render layers node and the file output node, for the caller's links.
    """
    scene.use_nodes = True
    scene.render.use_compositing = True
    tree = scene.node_tree
    layers = next(n for n in tree.nodes if n.bl_idname == "CompositorNodeRLayers")
    out = tree.nodes.new("CompositorNodeOutputFile")
    out.base_path = str(folder)
    out.format.file_format = "OPEN_EXR" if exr else "PNG"
    out.format.color_mode = "BW"
    if exr:
        out.format.color_depth = "32"
        out.format.exr_codec = "ZIP"
    else:
        out.format.color_depth = "16"
        out.format.compression = 0
    out.format.color_management = "OVERRIDE"
    out.format.view_settings.view_transform = "Raw"  # data, not colour
    out.file_slots.clear()
    for name in slots:
        out.file_slots.new(f"{name}_")
    return tree, layers, out
