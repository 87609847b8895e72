"""Which Mitsuba variant renders a quickstart job faster here: ``scalar_rgb`` (no system library)
or ``llvm_ad_rgb`` (JIT-compiled; Debian's libLLVM). Each variant runs in its own process and
renders the quickstart's five objects in the studio HDRI and on white, turned to ``--jobs`` yaws,
at the model's framing (224² crop of 256²), 4 samples + OpenImageDenoise, with the mask pass off
and on. The first render of each object (the load, and llvm's kernel compilation) is left out;
the median of the rest is printed per variant. The machine is shared: run it twice.

    .venv/bin/python benchmarks/mitsuba_variant.py [--jobs 6]
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import statistics
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
VARIANTS = ("scalar_rgb", "llvm_ad_rgb")


def _measure(variant: str, jobs: int, passes: tuple[str, ...], out) -> None:
    import sweep3d
    import sweep3d.stages.render.mitsuba.backend as engines
    from sweep3d.assets.sources import builtin_hdris, materialise_mesh
    from sweep3d.spec.models import KeyLightSpec
    from sweep3d.stages.render.controls import RENDERED_CONTROLS
    from sweep3d.stages.render.mitsuba.scene import MitsubaScene
    from sweep3d.stages.render.worker import render_job
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderJob, RenderSettings

    engines.MITSUBA_VARIANT = variant
    spec = sweep3d.load(REPO / "specs" / "quickstart.toml").spec
    scratch = Path(tempfile.mkdtemp(prefix="mitsuba-variant-"))
    scene = MitsubaScene(RenderSettings(resolution=256, crop=224, samples=4, denoise=True, passes=passes,
                                        engine="mitsuba"), scratch)
    orientation = RENDERED_CONTROLS.get("orientation")("orientation", "orientation")
    envs = [EnvironmentRef(hdri=str(builtin_hdris()["studio"])), EnvironmentRef(color=(1.0, 1.0, 1.0),
                                                                                  key_light=KeyLightSpec())]
    seconds = []
    for obj in spec.objects:
        mesh = str(materialise_mesh(spec.meshes[obj.name], scratch))
        for env in envs:
            for i in range(jobs + 1):
                started = time.perf_counter()
                job = RenderJob(f"k{i}", mesh, env, ((orientation, orientation.params({"yaw": 360.0 * i / jobs})),),
                                blob=str(scratch / "x.png"))
                reply = render_job(scene, job)
                assert reply.ok, reply.error
                if i:
                    seconds.append(time.perf_counter() - started)
    out.put(statistics.median(seconds))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=6)
    args = parser.parse_args()
    ctx = mp.get_context("spawn")
    for passes in ((), ("mask", "depth")):
        for variant in VARIANTS:
            queue = ctx.Queue()
            process = ctx.Process(target=_measure, args=(variant, args.jobs, passes, queue))
            process.start()
            median = queue.get()
            process.join()
            print(f"{variant:12s} passes={'+'.join(passes) or 'none':11s} {median * 1000:7.0f} ms per render (median)")


if __name__ == "__main__":
    main()
