"""Which samples and denoiser quality Mitsuba's renders need: each setting against Mitsuba's own
512-sample render of the same job (not against Cycles: a second renderer is judged by its own
converged image), on the quickstart's toaster, cheeseburger and reflex camera in the studio HDRI
and on white at 3 yaws each (224² of 256²). Prints per setting the median CPU milliseconds per
render (the path tracer, the denoiser's albedo and normals, OpenImageDenoise) and the PSNR against
the reference (median and worst). The engine's setting is ``DENOISE_QUALITY`` in
``stages/render/mitsuba/scene.py``; RESULTS.md, "Mitsuba at a fraction of Cycles' cost".

    .venv/bin/python benchmarks/mitsuba_denoise.py
"""

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
#: (samples, OpenImageDenoise quality or None for no denoiser)
SETTINGS = [(4, "high"), (4, "balanced"), (4, "fast"), (8, "balanced"), (8, "fast"), (16, None), (32, None)]


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(1 / np.mean((a - b) ** 2)))


def finish(rgb: np.ndarray, alpha: np.ndarray, background, srgb) -> np.ndarray:
    """The image as the engine stores it: the sRGB curve, a plain background composited behind."""
    if background is None:
        return srgb(rgb)
    straight = srgb(rgb / np.maximum(alpha, 1e-6))
    return straight * alpha + np.asarray(background, dtype=np.float32) * (1 - alpha)


def main() -> None:
    import pyoidn

    import sweep3d
    from sweep3d.assets.sources import builtin_hdris, materialise_mesh
    from sweep3d.spec.models import KeyLightSpec
    from sweep3d.stages.render.mitsuba import translate
    from sweep3d.stages.render.mitsuba.scene import FILTER_RADIUS, MitsubaScene, srgb
    from sweep3d.stages.render.state import SceneState
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderSettings

    spec = sweep3d.load(REPO / "specs" / "quickstart.toml").spec
    scratch = Path(tempfile.mkdtemp())
    scene = MitsubaScene(RenderSettings(resolution=256, crop=224, samples=4, denoise=True, engine="mitsuba",
                                        variant="llvm_ad_rgb"), scratch)
    mi = scene.mi
    aux_integrator = mi.load_dict({"type": "aov", "aovs": "albedo:albedo,normal:sh_normal"})
    results: dict = {setting: [] for setting in SETTINGS}
    environments = [EnvironmentRef(hdri=str(builtin_hdris()["studio"])),
                    EnvironmentRef(color=(1.0, 1.0, 1.0), key_light=KeyLightSpec())]
    for index in (4, 2, 3):
        mesh = str(materialise_mesh(spec.meshes[spec.objects[index].name], scratch))
        for environment in environments:
            scene.prepare(mesh, environment)
            for yaw in (0, 120, 240):
                scene.pose_scene(SceneState(yaw=yaw, elevation=20))
                s, background = scene.settings, scene.background()
                path = {"type": "path", "max_depth": s.max_bounces + 1, "hide_emitters": background is not None}
                loaded = scene.kept.scene_for(scene.describe(path, translate.camera(scene.state, s.resolution, s.crop,
                                                                                     FILTER_RADIUS)))
                image = np.asarray(mi.render(loaded, spp=512, seed=7), dtype=np.float32)
                reference = finish(np.maximum(image[..., :3], 0), np.clip(image[..., 3:4], 0, 1), background, srgb)
                for samples, quality in SETTINGS:
                    started = time.process_time()
                    image = np.asarray(mi.render(loaded, spp=samples, seed=1), dtype=np.float32)
                    rgb, alpha = np.maximum(image[..., :3], 0), np.clip(image[..., 3:4], 0, 1)
                    if quality:
                        aux = np.asarray(mi.render(loaded, integrator=aux_integrator, spp=samples, seed=1),
                                         dtype=np.float32)
                        rgb = np.maximum(pyoidn.denoise(
                            np.ascontiguousarray(rgb), np.ascontiguousarray(np.clip(aux[..., -6:-3], 0, 1)),
                            np.ascontiguousarray(np.clip(aux[..., -3:], -1, 1)), hdr=True, clean_aux=True,
                            quality=quality), 0)
                    out = finish(rgb, alpha, background, srgb)
                    results[samples, quality].append((time.process_time() - started, psnr(reference, out)))
    for (samples, quality), values in results.items():
        print(f"{samples:3d} samples, denoiser {quality or 'none':9s}: "
              f"{1000 * statistics.median(v[0] for v in values):4.0f} ms CPU, "
              f"PSNR against 512 samples {statistics.median(v[1] for v in values):.1f} dB "
              f"(worst {min(v[1] for v in values):.1f})")


if __name__ == "__main__":
    main()
