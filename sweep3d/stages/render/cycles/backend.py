"""The Cycles engine's :class:`~..backend.Backend`: the default, and the reference the others match.

Cycles renders every built-in control and every pass, runs controls' ``edit()`` on Blender's live
scene, and renders on the CPU or NVIDIA GPUs. It adds nothing to the render key, so its keys are
those from before the engine was a choice.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sweep3d.stages.render.backend import Backend

if TYPE_CHECKING:
    from sweep3d.stages.render.cycles.scene import BlenderScene

#: Seconds per sample at 224² on a 2-core CPU, measured with bench (``plan``'s fallback estimate).
SECONDS_PER_SAMPLE_224 = 0.034


class CyclesBackend(Backend):
    """Blender's Cycles, in a worker that imports bpy once and keeps its scene."""

    name = "cycles"
    title = "Cycles"
    devices = ("cpu", "cuda", "optix")
    edits_scene = True
    seconds_224 = (SECONDS_PER_SAMPLE_224, 0.02)

    def scene(self, settings, scratch, log=None, gpu=None) -> BlenderScene:
        """A ``BlenderScene`` (imported only now: Mitsuba's workers never load Blender)."""
        from sweep3d.stages.render.cycles.scene import BlenderScene

        return BlenderScene(settings, scratch, log, gpu)

    def key(self) -> None:
        """None: Cycles' render keys are those from before there was a choice of engine."""
        return None
