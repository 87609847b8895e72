"""A job's beauty and aux renders, replayed by Dr.Jit without tracing them again.

Why: under ``llvm_ad_rgb`` each ``mitsuba.render`` call traces the whole path tracer in Python
and C++ before its (cached) kernels run, about half of a 224², 4-sample render's CPU time. A
frozen function (``drjit.freeze``) records the kernel launches once per scene structure and then
replays them with the kept scene's current parameters (its inputs are traversed on every call, so
a changed pose, camera, light or material reaches the kernels; a changed structure records again).
The pixels are the traced render's to a float's last bits (tests/stages/render/test_mitsuba_kept.py
compares renders replayed by a kept worker with fresh ones). ``scalar_rgb`` has nothing to trace:
it renders directly.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Recordings a worker keeps (least recently used out): one per scene structure (object, environment,
#: lights' kinds, samples), and the render stage hands a worker its jobs grouped by them.
MAX_RECORDINGS = 4


class FrozenRender:
    """Renders a scene's beauty image and, when given an aux integrator, the denoiser's albedo and normals."""

    def __init__(self, mi: Any) -> None:
        self.mi = mi
        self.replayed: Any = None
        self.primed: Any = None  # the latest scene rendered once before its recording (_prime)
        self.depth: Any = None  # the priming render's integrator, loaded once
        if not mi.variant().startswith("scalar"):
            import drjit as dr

            # the same structure in a new scene records again: a worker meets many, never warned of
            self.replayed = dr.freeze(self._render, limit=MAX_RECORDINGS, warn_after=1 << 30)

    def _render(self, scene: Any, seed: Any, spp: int, aux: Any, sensors: tuple[int, int]) -> tuple[Any, Any]:
        mi = self.mi
        beauty = mi.render(scene, sensor=sensors[0], spp=spp, seed=seed)
        if aux is None:
            return beauty, None
        return beauty, mi.render(scene, sensor=sensors[1], integrator=aux, spp=spp, seed=seed)

    def __call__(self, scene: Any, spp: int, seed: int, aux: Any = None,
                 sensors: tuple[int, int] = (0, 0)) -> tuple[np.ndarray, np.ndarray | None]:
        """The beauty image (H, W, 4: RGB and alpha) and the aux integrator's (or None), float32,
        through the scene's sensors of those numbers."""
        if self.replayed is None:
            beauty, channels = self._render(scene, seed, spp, aux, sensors)
        else:
            self._prime(scene, sensors, aux)
            beauty, channels = self.replayed(scene, self.mi.UInt32(seed), spp, aux, sensors)
        return (np.asarray(beauty, dtype=np.float32),
                None if channels is None else np.asarray(channels, dtype=np.float32))

    def _prime(self, scene: Any, sensors: tuple[int, int], aux: Any) -> None:
        """A newly loaded scene's first render sets up state that its second finds changed, which
        would record the frozen render twice (the first job of each scene structure paying twice
        a full trace): a one-sample render of the camera's depth, and of the aux integrator's
        channels through its sensor, sets it up for a few milliseconds instead."""
        if scene is self.primed:
            return
        mi = self.mi
        if self.depth is None:
            self.depth = mi.load_dict({"type": "aov", "aovs": "depth:depth"})
        mi.render(scene, sensor=sensors[0], integrator=self.depth, spp=1, seed=0)
        if aux is not None:
            mi.render(scene, sensor=sensors[1], integrator=aux, spp=1, seed=0)
        self.primed = scene
