"""A job's beauty and aux renders, replayed by Dr.Jit without tracing them again.

Why: under ``llvm_ad_rgb`` each ``mitsuba.render`` call traces the whole path tracer in Python
and C++ before its (cached) kernels run, about half of a 224², 4-sample render's CPU time. A
frozen function (``drjit.freeze``) records the kernel launches once per scene structure and then
replays them with the kept scene's current parameters (its inputs are traversed on every call, so
a changed pose, camera, light or material reaches the kernels; a changed structure records again).
Dr.Jit cannot see what a scene's C++ objects hold outside its arrays (a filter's type, an
integrator's depth, whether emitters are hidden), so the caller names the structure (the kept
scene's key) and a new one is recorded apart: a replay never serves another structure.

The render itself is sweep3d's loop over Mitsuba's parts, not ``mitsuba.render``: the same
samples, camera rays and path tracer as ``mitsuba.render`` through a box-filtered film
(``tests/stages/render/test_mitsuba_kept.py`` compares the two), a pixel the mean of its own
samples taken by Dr.Jit's block sums in place of the film's atomic additions, and the denoiser's
albedo and normals read along the same rays in the same kernel (a second pass through a twin
camera before). Mitsuba's film splatting each sample over the 2×2 pixels a tent reaches cost 20
of a 224², 4-sample render's 70 ms CPU, whether by its atomic additions or by block sums per
neighbour; sampling the tent by importance (each sample's ray offset by the tent, counted in its
own pixel) costs nothing but leaves each pixel its own 4 samples, 0.9 dB further from the
512-sample render than the splatted tent where the box is 0.4 dB (benchmarks/RESULTS.md,
"2026-11-29: the film's splatting left out").

``scalar_rgb`` has nothing to trace: it renders with ``mitsuba.render``, its film splatting the
tent (``scene.FILTER_RADIUS``) and the aux pass through a box-filtered twin camera (``scene.aux_sensor``).
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
            self.replayed = dr.freeze(self._traced, limit=MAX_RECORDINGS, warn_after=1 << 30)

    def _rendered(self, scene: Any, seed: int, spp: int, aux: Any, sensors: tuple[int, int]) -> tuple[Any, Any]:
        """``scalar_rgb``: Mitsuba's own render, the aux pass through the sensor ``sensors[1]``."""
        mi = self.mi
        beauty = mi.render(scene, sensor=sensors[0], spp=spp, seed=seed)
        if aux is None:
            return beauty, None
        return beauty, mi.render(scene, sensor=sensors[1], integrator=aux, spp=spp, seed=seed)

    def _traced(self, scene: Any, seed: Any, spp: int, aux: Any, sensor: int, structure: int) -> list[Any]:
        """The pixels' channels (R, G, B, alpha, then the aux integrator's), each a flat array of
        the crop's pixels, row by row, the mean of each pixel's ``spp`` samples (a box filter).
        ``structure`` only keys the recording (the module docstring)."""
        import drjit as dr

        mi = self.mi
        camera = scene.sensors()[sensor]
        width, height = (int(v) for v in camera.film().crop_size())
        sampler = camera.sampler().clone()  # seeded as mitsuba.render seeds the sensor's sampler
        sampler.set_sample_count(spp)
        spp = sampler.sample_count()  # the multi-jittered grid's: 5 asked are 6 (2 × 3), as mitsuba.render takes
        sampler.set_samples_per_wavefront(spp)
        sampler.seed(seed, width * height * spp)
        pixel = dr.arange(mi.UInt32, width * height * spp) // spp  # a pixel's samples side by side
        row = pixel // width
        position = (mi.Vector2f(mi.Float(pixel - row * width), mi.Float(row)) + sampler.next_2d()) \
            * mi.ScalarVector2f(1.0 / width, 1.0 / height)
        aperture = sampler.next_2d() if camera.needs_aperture_sample() else mi.Point2f(0.5)
        time = camera.shutter_open()
        if camera.shutter_open_time() > 0:
            time += sampler.next_1d() * camera.shutter_open_time()
        ray, weight = camera.sample_ray_differential(time, 0.0, position, aperture)
        ray.scale_differential(dr.rsqrt(spp))
        radiance, valid, _ = scene.integrator().sample(scene, sampler, ray, None, True)
        radiance = radiance * weight
        channels = [radiance.x, radiance.y, radiance.z, dr.select(valid, 1.0, 0.0)]
        if aux is not None:
            channels += list(aux.sample(scene, sampler, ray, None, True)[2])
        dr.eval(channels)  # one kernel: each block sum below would otherwise trace the path tracer again
        return [dr.block_sum(channel, spp) / spp for channel in channels]

    def __call__(self, scene: Any, spp: int, seed: int, aux: Any = None, sensors: tuple[int, int] = (0, 0),
                 structure: int = 0) -> tuple[np.ndarray, np.ndarray | None]:
        """The beauty image (H, W, 4: RGB and alpha) and the aux integrator's (H, W, its channels;
        or None), float32, through the camera ``sensors[0]``. Under a JIT variant a box filter, the
        recording keyed by ``structure``; under ``scalar_rgb`` Mitsuba's render and film, the aux
        pass through the sensor ``sensors[1]``."""
        if self.replayed is None:
            beauty, channels = self._rendered(scene, seed, spp, aux, sensors)
            return (np.asarray(beauty, dtype=np.float32),
                    None if channels is None else np.asarray(channels, dtype=np.float32))
        if scene.sensors()[sensors[0]].needs_aperture_sample():  # a thin lens holds a value Dr.Jit cannot
            out = self._traced(scene, self.mi.UInt32(seed), spp, aux, sensors[0], structure)  # see: traced each time
        else:
            self._prime(scene, sensors[0], aux)
            out = self.replayed(scene, self.mi.UInt32(seed), spp, aux, sensors[0], structure)
        width, height = (int(v) for v in scene.sensors()[sensors[0]].film().crop_size())
        image = np.stack([np.asarray(channel, dtype=np.float32) for channel in out], axis=-1)
        image = image.reshape(height, width, len(out))
        return image[..., :4], (image[..., 4:] if aux is not None else None)

    def _prime(self, scene: Any, sensor: int, aux: Any) -> None:
        """A newly loaded scene's first render sets up state that its second finds changed, which
        would record the frozen render twice (the first job of each scene structure paying twice
        a full trace): a one-sample render of the camera's depth, and of the aux integrator's
        channels, sets it up for a few milliseconds instead."""
        if scene is self.primed:
            return
        mi = self.mi
        if self.depth is None:
            self.depth = mi.load_dict({"type": "aov", "aovs": "depth:depth"})
        mi.render(scene, sensor=sensor, integrator=self.depth, spp=1, seed=0)
        if aux is not None:
            mi.render(scene, sensor=sensor, integrator=aux, spp=1, seed=0)
        self.primed = scene
