"""Render: Blender (Cycles on the CPU, or NVIDIA GPUs) in persistent worker processes.

This package's public API never imports bpy; only :mod:`.worker` (in child processes) does.
"""

from sweep3d.stages.render.controls import RENDERED_CONTROLS, RenderedControl
from sweep3d.stages.render.stage import LOCAL, Executor, RenderStage, render_settings
from sweep3d.stages.render.state import SceneState

__all__ = ["LOCAL", "RENDERED_CONTROLS", "Executor", "RenderStage", "RenderedControl", "SceneState",
           "render_settings"]
