"""What one render costs each engine on the quickstart's scenes, both measured in one sitting.

Each engine renders the quickstart's distinct render jobs (5 objects × 4 environments × 6 yaws ×
2 camera heights at the model's framing, 224² of 256², 4 samples + OpenImageDenoise; its blur
needs no render) in a process of its own, through a render worker's own code (``make_scene`` and
``render_job``, world by world and object by object as the render stage hands them out), with no
pool, queue or store around it. The engines alternate (cycles, mitsuba, mitsuba, cycles, …), and
each prints, per render, the median wall seconds and the median CPU seconds of the whole process
(every thread's: the figure a shared machine distorts least), leaving out the first job of each
object and environment (where each engine loads them; shown apart). The load average is printed
before and after.

    .venv/bin/python benchmarks/engine_cost.py [--rounds 2] [--every 1]

``--every N`` renders every N-th job only (a quicker, rougher figure).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from engines import derived_spec  # noqa: E402  (the quickstart with an engine and no blur, as there)

ENGINES = ("cycles", "mitsuba")


def child(engine: str, every: int) -> None:
    """Render the jobs with ``engine`` in this process; print one JSON line of per-job seconds."""
    import sweep3d
    from sweep3d.cache import Store
    from sweep3d.stages.render.render_stage import _groups
    from sweep3d.stages.render.worker import make_scene, render_job
    from sweep3d.stages.render.worker_protocol import RenderSettings

    folder = Path(tempfile.mkdtemp(prefix=f"engine-cost-{engine}-"))
    experiment = sweep3d.load(derived_spec(folder, engine, samples_per_dim=6))  # the quickstart's 6 yaws
    status = experiment.plan()
    plan = status.plan
    unique = list({job.render_key: job for job in plan.jobs}.values())
    store = Store(experiment.store)
    jobs = [j for group in _groups(plan, store, unique, set()) for j in group][::every]
    settings = RenderSettings.from_spec(plan.spec.render, plan.framing, status.passes, plan.device)
    scene = make_scene(settings, folder / "scratch")
    (folder / "scratch").mkdir(exist_ok=True)
    first, later, seen = [], [], set()
    for job in jobs:
        wall, cpu = time.perf_counter(), time.process_time()
        reply = render_job(scene, job)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        if not reply.ok:
            sys.exit(f"{engine}: {reply.error}")
        scene_of = (job.mesh, job.environment_name)
        (later if scene_of in seen else first).append((wall, cpu))
        seen.add(scene_of)
    print(json.dumps({"engine": engine, "first": first, "later": later}))


def load_average() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "unknown"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--every", type=int, default=1)
    parser.add_argument("--child", choices=ENGINES, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child, args.every)
        return
    print(f"load average before: {load_average()}", flush=True)
    medians: dict[str, list[tuple[float, float]]] = {e: [] for e in ENGINES}
    for round_ in range(args.rounds):
        for engine in (ENGINES if round_ % 2 == 0 else ENGINES[::-1]):
            out = subprocess.run([sys.executable, __file__, "--child", engine, "--every", str(args.every)],
                                 capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1]
            got = json.loads(out)
            later = got["later"]
            wall = statistics.median(w for w, _ in later)
            cpu = statistics.median(c for _, c in later)
            loads = statistics.median(w for w, _ in got["first"])
            medians[engine].append((wall, cpu))
            print(f"round {round_} {engine:8s} per render: {wall:.3f} s wall, {cpu:.3f} s CPU (medians of "
                  f"{len(later)}); first job of each scene {loads:.2f} s (median of {len(got['first'])}); "
                  f"load {load_average()}", flush=True)
    print(f"load average after: {load_average()}")
    for i, label in ((0, "wall"), (1, "CPU")):
        per = {e: statistics.median(m[i] for m in medians[e]) for e in ENGINES}
        print(f"mitsuba / cycles, {label} per render: {per['mitsuba'] / per['cycles']:.2f} "
              f"({per['mitsuba']:.3f} / {per['cycles']:.3f} s)")


if __name__ == "__main__":
    main()
