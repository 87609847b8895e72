"""Render: the scene in persistent worker processes, by an engine behind one seam.

Each engine is a folder with a :class:`~.backend.Backend` (``cycles/``: Blender's Cycles on the
CPU or NVIDIA GPUs; ``mitsuba/``: Mitsuba 3), registered by name in :data:`~.backends.BACKENDS`.
This package's public API never imports bpy or mitsuba; only the workers (child processes) do.
"""

from __future__ import annotations

__all__ = [
    "BACKENDS", "Backend", "COLUMNS", "Child", "Executor", "LOCAL", "Look", "RENDERED_CONTROLS", "RenderInfo", "RenderScene", "RenderStage",
    "RenderedControl", "SENSOR_WIDTH_MM", "SIDES", "SceneEdit", "SceneState", "check_engine",
    "connect", "cycles_only_defaults", "death_cause", "describe_materials", "device_note", "duration", "engine_key",
    "join_ray", "ray_session", "variant_note",
    "estimate_render_seconds", "frame_fields", "in_frame", "in_frame_many", "missing_gpu_warning",
    "object_error", "paint_objects", "parts_keys", "plan_device", "remove_stale_scratch",
    "render_settings", "render_template", "resolve_device", "scene_key", "scratch_root",
    "slow_render_warning", "truth_keys"
]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.stages.render.backend import Backend, RenderScene
    from sweep3d.stages.render.backends import (
        BACKENDS,
        check_engine,
        cycles_only_defaults,
        engine_key,
        plan_device,
        variant_note,
    )
    from sweep3d.stages.render.child import Child
    from sweep3d.stages.render.controls.rendered_control import RENDERED_CONTROLS, RenderedControl, frame_fields
    from sweep3d.stages.render.cycles.describe import COLUMNS, describe_materials
    from sweep3d.stages.render.cycles.paint import SIDES, paint_objects
    from sweep3d.stages.render.cycles.scene_edit import SceneEdit
    from sweep3d.stages.render.device import device_note, missing_gpu_warning, resolve_device
    from sweep3d.stages.render.estimate import duration, estimate_render_seconds, slow_render_warning
    from sweep3d.stages.render.pool import death_cause, remove_stale_scratch, scratch_root
    from sweep3d.stages.render.ray_pool import connect, ray_session
    from sweep3d.stages.render.ray_pool import join as join_ray
    from sweep3d.stages.render.render_keys import parts_keys, render_template, scene_key, truth_keys
    from sweep3d.stages.render.render_stage import LOCAL, Executor, RenderStage, object_error, render_settings
    from sweep3d.stages.render.state import SENSOR_WIDTH_MM, SceneState, in_frame, in_frame_many
    from sweep3d.stages.render.worker_protocol import Look, RenderInfo

__getattr__, __dir__ = _exports(__name__, {
    "BACKENDS": ("sweep3d.stages.render.backends", "BACKENDS"),
    "Backend": ("sweep3d.stages.render.backend", "Backend"),
    "RenderScene": ("sweep3d.stages.render.backend", "RenderScene"),
    "COLUMNS": ("sweep3d.stages.render.cycles.describe", "COLUMNS"),
    "Child": ("sweep3d.stages.render.child", "Child"),
    "Executor": ("sweep3d.stages.render.render_stage", "Executor"),
    "LOCAL": ("sweep3d.stages.render.render_stage", "LOCAL"),
    "Look": ("sweep3d.stages.render.worker_protocol", "Look"),
    "RENDERED_CONTROLS": ("sweep3d.stages.render.controls.rendered_control", "RENDERED_CONTROLS"),
    "RenderInfo": ("sweep3d.stages.render.worker_protocol", "RenderInfo"),
    "RenderStage": ("sweep3d.stages.render.render_stage", "RenderStage"),
    "RenderedControl": ("sweep3d.stages.render.controls.rendered_control", "RenderedControl"),
    "SENSOR_WIDTH_MM": ("sweep3d.stages.render.state", "SENSOR_WIDTH_MM"),
    "SIDES": ("sweep3d.stages.render.cycles.paint", "SIDES"),
    "SceneEdit": ("sweep3d.stages.render.cycles.scene_edit", "SceneEdit"),
    "SceneState": ("sweep3d.stages.render.state", "SceneState"),
    "check_engine": ("sweep3d.stages.render.backends", "check_engine"),
    "connect": ("sweep3d.stages.render.ray_pool", "connect"),
    "cycles_only_defaults": ("sweep3d.stages.render.backends", "cycles_only_defaults"),
    "ray_session": ("sweep3d.stages.render.ray_pool", "ray_session"),
    "join_ray": ("sweep3d.stages.render.ray_pool", "join"),
    "describe_materials": ("sweep3d.stages.render.cycles.describe", "describe_materials"),
    "death_cause": ("sweep3d.stages.render.pool", "death_cause"),
    "device_note": ("sweep3d.stages.render.device", "device_note"),
    "duration": ("sweep3d.stages.render.estimate", "duration"),
    "engine_key": ("sweep3d.stages.render.backends", "engine_key"),
    "variant_note": ("sweep3d.stages.render.backends", "variant_note"),
    "estimate_render_seconds": ("sweep3d.stages.render.estimate", "estimate_render_seconds"),
    "frame_fields": ("sweep3d.stages.render.controls.rendered_control", "frame_fields"),
    "in_frame": ("sweep3d.stages.render.state", "in_frame"),
    "in_frame_many": ("sweep3d.stages.render.state", "in_frame_many"),
    "missing_gpu_warning": ("sweep3d.stages.render.device", "missing_gpu_warning"),
    "object_error": ("sweep3d.stages.render.render_stage", "object_error"),
    "paint_objects": ("sweep3d.stages.render.cycles.paint", "paint_objects"),
    "parts_keys": ("sweep3d.stages.render.render_keys", "parts_keys"),
    "plan_device": ("sweep3d.stages.render.backends", "plan_device"),
    "remove_stale_scratch": ("sweep3d.stages.render.pool", "remove_stale_scratch"),
    "render_settings": ("sweep3d.stages.render.render_stage", "render_settings"),
    "render_template": ("sweep3d.stages.render.render_keys", "render_template"),
    "resolve_device": ("sweep3d.stages.render.device", "resolve_device"),
    "scene_key": ("sweep3d.stages.render.render_keys", "scene_key"),
    "scratch_root": ("sweep3d.stages.render.pool", "scratch_root"),
    "slow_render_warning": ("sweep3d.stages.render.estimate", "slow_render_warning"),
    "truth_keys": ("sweep3d.stages.render.render_keys", "truth_keys"),
})
