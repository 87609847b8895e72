"""Resident memory over a long run with many scene switches (issue: memory that stays flat).

Runs `sweep3d run` (a fresh interpreter, a fresh store) over ``--objects`` meshes of Sweet Home
3D's furniture × 3 environments (white, two HDRIs) × ``--per-scene`` random poses, at 32² and
1 sample: many renders, a mesh and world switch every few of them. Every half second it samples
the resident memory (VmRSS) of the parent and of each render worker from /proc, and reads the
run's progress lines (printed every 10 s when the output is not a terminal) for the renders done,
so memory is plotted against renders. Each ``--budget`` is one run with that
``[render] worker_memory`` (0: no limit, the "before"); the plot is an SVG.

    .venv/bin/python benchmarks/memory.py [--objects 200] [--per-scene 17] [--budget 0 700] [--svg docs/images/memory.svg]
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import threading
import time
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FURNITURE = Path("/usr/share/sweethome3d/furniture")
PROGRESS = re.compile(r"^render: (\d+)/(\d+)")


def meshes(count: int) -> list[str]:
    """The first ``count`` OBJ members of the furniture libraries, in a fixed order."""
    out = []
    for library in sorted(FURNITURE.glob("*.sh3f")):
        with zipfile.ZipFile(library) as archive:
            out += [f"{library}#{name}" for name in sorted(archive.namelist()) if name.endswith(".obj")]
    if len(out) < count:
        raise SystemExit(f"only {len(out)} meshes in {FURNITURE}")
    return out[:count]


def spec_text(objects: list[str], per_scene: int, budget: int) -> str:
    blocks = [f'[[objects]]\nname = "o{i}"\nmesh = "{mesh}"\nlabels = ["carton"]\n' for i, mesh in enumerate(objects)]
    return f"""
[experiment]
name = "memory"
store = "store"
max_archive_mb = 2048

[render]
resolution = 32
samples = 1
denoise = false
worker_memory = {budget}

[policy]
type = "random"
samples = {per_scene}

[[environments]]
name = "white"
color = [1.0, 1.0, 1.0]

[[environments]]
name = "studio"
hdri = "builtin:studio"

[[environments]]
name = "forest"
hdri = "builtin:forest"

[[controls]]
type = "orientation"
yaw = {{ range = [-180, 180] }}

{chr(10).join(blocks)}"""


def rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def children(pid: int) -> list[int]:
    try:
        return [int(p) for p in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def measure(folder: Path, objects: list[str], per_scene: int, budget: int) -> dict:
    """One run: samples of (seconds, renders done, parent MB, [worker MB ...])."""
    folder.mkdir(parents=True)
    (folder / "spec.toml").write_text(spec_text(objects, per_scene, budget))
    started = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "sweep3d", "run", "spec.toml", "--no-report"], cwd=folder,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"})
    done = [0]
    log: list[str] = []

    def read() -> None:
        for line in proc.stdout:  # type: ignore[union-attr]
            log.append(line)
            match = PROGRESS.match(line.strip())
            if match:
                done[0] = int(match.group(1))

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    samples = []
    workers_seen: set[int] = set()
    while proc.poll() is None:
        sizes = {c: rss_mb(c) for c in children(proc.pid) if "spawn_main" in _cmdline(c)}
        sizes = {c: m for c, m in sizes.items() if m is not None and m > 100}  # a render worker holds bpy
        workers_seen.update(sizes)
        samples.append((time.perf_counter() - started, done[0], rss_mb(proc.pid) or 0.0, list(sizes.values())))
        time.sleep(0.5)
    reader.join(timeout=5)
    if proc.returncode not in (0, 1):  # 1: some jobs failed (a mesh Blender cannot import), said in the log
        raise RuntimeError(f"sweep3d run failed ({proc.returncode}):\n{''.join(log[-30:])}")
    renders = len(objects) * 3 * per_scene
    return {"budget": budget, "seconds": time.perf_counter() - started, "samples": samples, "renders": renders,
            "workers": len(workers_seen), "log": "".join(log[-12:])}


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _at(run: dict, share: float) -> tuple[float, float]:
    """(largest worker, parent) RSS at the first sample with ``share`` of the renders done."""
    for _, done, parent, workers in run["samples"]:
        if done >= share * run["renders"] and workers:
            return max(workers), parent
    return 0.0, 0.0


def svg(runs: list[dict], path: Path) -> None:
    """RSS (MB) against renders done: the parent and the largest worker, one colour per budget."""
    width, height, left, bottom = 720, 360, 60, 40
    top = max(max([s[2] for s in r["samples"]] + [max(s[3], default=0) for s in r["samples"]]) for r in runs) * 1.1
    most = max(r["renders"] for r in runs)
    x = lambda n: left + (width - left - 20) * n / most  # noqa: E731
    y = lambda mb: height - bottom - (height - bottom - 20) * mb / top  # noqa: E731
    colours = ["#c0392b", "#2471a3", "#229954", "#7d3c98"]
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-family="sans-serif" '
             f'font-size="12"><rect width="100%" height="100%" fill="white"/>',
             f'<line x1="{left}" y1="{y(0)}" x2="{width - 20}" y2="{y(0)}" stroke="black"/>',
             f'<line x1="{left}" y1="{y(0)}" x2="{left}" y2="20" stroke="black"/>',
             f'<text x="{width / 2}" y="{height - 8}" text-anchor="middle">renders done</text>',
             f'<text x="14" y="{height / 2}" transform="rotate(-90 14 {height / 2})" text-anchor="middle">resident '
             f'memory (MB)</text>']
    for tick in range(0, int(top) + 1, 500):
        parts.append(f'<text x="{left - 6}" y="{y(tick) + 4}" text-anchor="end">{tick}</text>')
    for tick in range(0, most + 1, max(1000, most // 5 // 1000 * 1000)):
        parts.append(f'<text x="{x(tick)}" y="{y(0) + 16}" text-anchor="middle">{tick:,}</text>')
    for i, run in enumerate(runs):
        colour = colours[i % len(colours)]
        name = "no limit" if run["budget"] == 0 else f"worker_memory = {run['budget']} MB"
        worker = " ".join(f"{x(s[1]):.1f},{y(max(s[3])):.1f}" for s in run["samples"] if s[3])
        parent = " ".join(f"{x(s[1]):.1f},{y(s[2]):.1f}" for s in run["samples"])
        parts.append(f'<polyline points="{worker}" fill="none" stroke="{colour}" stroke-width="1.5"/>')
        parts.append(f'<polyline points="{parent}" fill="none" stroke="{colour}" stroke-width="1.5" '
                     f'stroke-dasharray="5,3"/>')
        parts.append(f'<text x="{left + 10}" y="{34 + 16 * i}" fill="{colour}">{name}: worker (solid), parent '
                     f'(dashed)</text>')
    parts.append("</svg>")
    path.write_text("\n".join(parts))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", type=int, default=200)
    parser.add_argument("--per-scene", type=int, default=17)
    parser.add_argument("--budget", type=int, nargs="+", default=[0, 700], help="[render] worker_memory per run (MB)")
    parser.add_argument("--svg", type=Path, default=None)
    args = parser.parse_args()
    objects = meshes(args.objects)
    runs = []
    with tempfile.TemporaryDirectory(prefix="sweep3d-memory-") as tmp:
        for budget in args.budget:
            run = measure(Path(tmp) / f"b{budget}", objects, args.per_scene, budget)
            runs.append(run)
            print(run["log"], flush=True)
    print(f"\n{args.objects} objects × 3 environments × {args.per_scene} poses at 32², 1 sample\n")
    print("| worker_memory | renders | wall | render workers started | worker RSS at 10 % / 50 % / 90 % of renders, "
          "max (MB) | parent RSS at 90 %, max (MB) |\n|---|---|---|---|---|---|")
    for run in runs:
        at = {share: _at(run, share) for share in (0.1, 0.5, 0.9)}
        worker = max(max(s[3]) for s in run["samples"] if s[3])
        print(f"| {run['budget'] or 'no limit'} | {run['renders']:,} | {run['seconds'] / 60:.1f} min | "
              f"{run['workers']} | {' / '.join(f'{at[k][0]:.0f}' for k in at)}, {worker:.0f} | "
              f"{at[0.9][1]:.0f}, {max(s[2] for s in run['samples']):.0f} |")
    if args.svg:
        svg(runs, args.svg)
        print(f"\nwrote {args.svg}")


if __name__ == "__main__":
    main()
