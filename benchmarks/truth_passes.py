"""What the truth passes cost per render: none, mask, mask + depth, with and without an occluder
(an occluder, or an object reaching out of the image, needs the visibility denominator's second,
index-only render; otherwise the mask is the whole silhouette).

Each configuration runs in a fresh worker process (passes are fixed per worker) rendering the
same jobs: one quickstart object (or ``--cube``) in the studio HDRI, turned to ``--jobs`` yaws,
at the model's framing (224² crop of 256²), 4 samples + OpenImageDenoise. The first render of
each process (the scene load) is left out; medians of the rest, then the median over ``--rounds``
rounds, the configurations taking turns in each (the machine is shared: interleaving spreads its
load over all of them alike).

    .venv/bin/python benchmarks/truth_passes.py [--jobs 12] [--rounds 3] [--cube]
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import statistics
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CONFIGS = [  # (name, passes, occlusion coverage, position x)
    ("no pass", (), 0.0, 0.0),
    ("mask", ("mask",), 0.0, 0.0),
    ("mask + depth", ("depth", "mask"), 0.0, 0.0),
    ("no pass, occluded", (), 0.3, 0.0),
    ("mask, occluded (denominator render)", ("mask",), 0.3, 0.0),
    ("mask + depth, occluded", ("depth", "mask"), 0.3, 0.0),
    ("no pass, half out of frame", (), 0.0, 0.9),
    ("mask, half out of frame (denominator render)", ("mask",), 0.0, 0.9),
]


def _measure(mesh: str, passes: tuple[str, ...], coverage: float, x: float, jobs: int, out) -> None:
    from sweep3d.assets.sources import builtin_hdris
    from sweep3d.stages.render.controls import RENDERED_CONTROLS
    from sweep3d.stages.render.cycles.scene import BlenderScene
    from sweep3d.stages.render.worker import render_job
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderJob, RenderSettings

    scratch = Path(tempfile.mkdtemp(prefix="truth-bench-"))
    scene = BlenderScene(RenderSettings(resolution=256, crop=224, samples=4, denoise=True, threads=2,
                                        passes=passes), scratch)
    env = EnvironmentRef(hdri=str(builtin_hdris()["studio"]))
    made = {name: RENDERED_CONTROLS.get(name)(name, name) for name in ("orientation", "occlusion", "position")}
    seconds, truth = [], []
    for i in range(jobs + 1):
        values = {"orientation": {"yaw": 360.0 * i / jobs}, "occlusion": {"coverage": coverage},
                  "position": {"x": x}}
        controls = tuple((made[n], made[n].params(v)) for n, v in values.items())
        started = time.perf_counter()
        reply = render_job(scene, RenderJob(f"k{i}", mesh, env, controls, blob=str(scratch / "x.png")))
        assert reply.ok, reply.error
        if i:
            seconds.append(time.perf_counter() - started)
            truth.append(reply.info.truth["truth_seconds"] if reply.info.truth else 0.0)
            how = reply.info.truth["silhouette"] if reply.info.truth else "-"
    out.send((statistics.median(seconds), statistics.median(truth), how))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=12)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--cube", action="store_true", help="the test cube instead of a quickstart mesh")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="truth-bench-"))
    if args.cube:
        from tests.helpers import write_cube

        mesh = str(write_cube(folder))
    else:
        import sweep3d
        from sweep3d.assets.sources import materialise_mesh

        spec = sweep3d.load(REPO / "specs" / "quickstart.toml").spec
        name = spec.objects[0].name
        mesh = str(materialise_mesh(spec.meshes[name], folder))
    print(f"mesh {Path(mesh).name}, {args.jobs} renders per configuration and round, {args.rounds} rounds, "
          f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    ctx = mp.get_context("spawn")
    found: dict[str, list[tuple[float, float, str]]] = {name: [] for name, *_ in CONFIGS}
    for _ in range(args.rounds):
        for name, passes, coverage, x in CONFIGS:
            here, there = ctx.Pipe()
            proc = ctx.Process(target=_measure, args=(mesh, passes, coverage, x, args.jobs, there))
            proc.start()
            found[name].append(here.recv())
            proc.join()
    print("| configuration | s/render | of which truth passes (read, encode, denominator) | denominator |")
    print("|---|---|---|---|")
    for name, rows in found.items():
        print(f"| {name} | {statistics.median(r[0] for r in rows):.3f} | {statistics.median(r[1] for r in rows):.3f} "
              f"| {rows[0][2]} |")
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
