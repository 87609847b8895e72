"""Render: Blender (Cycles on the CPU, or NVIDIA GPUs) in persistent worker processes.

This package's public API never imports bpy; only :mod:`.worker` (in child processes) does.
"""

from __future__ import annotations

__all__ = ["LOCAL", "RENDERED_CONTROLS", "Executor", "RenderStage", "RenderedControl", "SceneState",
           "render_settings"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.lazy import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.stages.render.controls import RENDERED_CONTROLS, RenderedControl
    from sweep3d.stages.render.stage import LOCAL, Executor, RenderStage, render_settings
    from sweep3d.stages.render.state import SceneState

__getattr__, __dir__ = _exports(__name__, {
    'Executor': ('sweep3d.stages.render.stage', 'Executor'),
    'LOCAL': ('sweep3d.stages.render.stage', 'LOCAL'),
    'RENDERED_CONTROLS': ('sweep3d.stages.render.controls', 'RENDERED_CONTROLS'),
    'RenderStage': ('sweep3d.stages.render.stage', 'RenderStage'),
    'RenderedControl': ('sweep3d.stages.render.controls', 'RenderedControl'),
    'SceneState': ('sweep3d.stages.render.state', 'SceneState'),
    'render_settings': ('sweep3d.stages.render.stage', 'render_settings'),
})
