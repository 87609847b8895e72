"""Render: Blender (Cycles on CPU) in persistent worker processes.

This package's public API never imports bpy; only :mod:`.worker` (in child processes) does.
"""

from sweep3d.stages.render.controls import RenderedControl
from sweep3d.stages.render.stage import render_stage
from sweep3d.stages.render.state import SceneState

__all__ = ["RenderedControl", "SceneState", "render_stage"]
