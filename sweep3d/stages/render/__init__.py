"""Render: the scene in persistent worker processes, by an engine behind one seam.

Each engine is a folder with a :class:`~.backend.Backend` (``cycles/``: Blender's Cycles on the
CPU or NVIDIA GPUs; ``mitsuba/``: Mitsuba 3), registered by name in :data:`~.backends.BACKENDS`.
This package's public API never imports bpy or mitsuba; only the workers (child processes) do.
"""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used.
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
    from sweep3d.stages.render.backends import backend as engine_backend  # `backend` is the protocol's module
    from sweep3d.stages.render.child import Child
    from sweep3d.stages.render.controls.rendered_control import RENDERED_CONTROLS, RenderedControl, frame_fields
    from sweep3d.stages.render.cycles.describe import COLUMNS, describe_materials
    from sweep3d.stages.render.cycles.paint import SIDES, paint_objects
    from sweep3d.stages.render.cycles.scene_edit import SceneEdit
    from sweep3d.stages.render.device import device_note, missing_gpu_warning, resolve_device
    from sweep3d.stages.render.early import drop as drop_early_worker
    from sweep3d.stages.render.early import start as start_early_worker
    from sweep3d.stages.render.estimate import duration, estimate_render_seconds, slow_render_warning
    from sweep3d.stages.render.pool import death_cause, remove_stale_scratch, scratch_root
    from sweep3d.stages.render.ray_pool import connect, ray_session
    from sweep3d.stages.render.ray_pool import join as join_ray
    from sweep3d.stages.render.render_keys import parts_keys, render_template, scene_key, truth_keys
    from sweep3d.stages.render.render_stage import LOCAL, Executor, RenderStage, object_error, render_settings
    from sweep3d.stages.render.state import SENSOR_WIDTH_MM, SceneState, in_frame, in_frame_many
    from sweep3d.stages.render.worker_protocol import Look, RenderInfo

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
