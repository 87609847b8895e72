"""Renders per second of the quickstart on the CPU, CUDA and OptiX (issue 25), and how far each
GPU back-end's pictures are from the CPU's.

A GPU machine often has Blender's Python (3.11) but not the rest of sweep3d's stack, so this is
measured with `bare_loop.py`, which needs bpy and numpy alone and enables a GPU with sweep3d's
own `gpus.enable`. Three steps:

    # where sweep3d is installed: the quickstart's 240 distinct renders, meshes and HDRIs copied
    .venv/bin/python benchmarks/gpu.py prepare /tmp/gpujobs
    # where the GPU is (Blender's Python with bpy and numpy), once per device and round
    python benchmarks/bare_loop.py /tmp/gpujobs/jobs.json /tmp/frames/optix-1 --device optix > optix-1.json
    # anywhere with numpy and Pillow: the table, from those JSON lines and frames
    python benchmarks/gpu.py report /tmp/frames

Where the GPU machine has no Python 3.11, `gpu_bundle.sh` packs this checkout's Python, bpy,
numpy, the libraries they load and the jobs into one tarball (in parts, if uploads are limited),
and `gpu_device.sh` unpacks it there and runs the last two steps for every device.

The first render of a process includes loading the device's kernels (on a GPU newer than the
kernels Blender ships, the driver compiles them from PTX once and caches them): the table gives
it apart, and renders/s counts the renders after it.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def prepare(folder: Path) -> None:
    """Write ``folder/jobs.json``: the quickstart's distinct renders, with every mesh folder and
    HDRI copied under ``folder`` and named relative to it, so that the folder can travel."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    from pipeline import bare_jobs

    work = folder / "work"
    path, n = bare_jobs(work)
    spec = json.loads(path.read_text())
    moved: dict[str, str] = {}
    for mesh in spec["meshes"]:
        source = Path(mesh)
        target = folder / "meshes" / source.parent.name
        shutil.copytree(source.parent, target, dirs_exist_ok=True)
        moved[mesh] = str((target / source.name).relative_to(folder))
    for name, env in spec["environments"].items():
        if env["hdri"]:
            source = Path(env["hdri"])
            target = folder / "hdri" / f"{name}{source.suffix}"
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, target)
            env["hdri"] = str(target.relative_to(folder))
    spec["meshes"] = [moved[m] for m in spec["meshes"]]
    for job in spec["jobs"]:
        job["mesh"] = moved[job["mesh"]]
    (folder / "jobs.json").write_text(json.dumps(spec))
    shutil.rmtree(work)
    print(f"{n} renders in {folder / 'jobs.json'}")


def mean_difference(a: Path, b: Path) -> float:
    """Mean |difference| in 8-bit levels between two frames' RGBA pixels."""
    import numpy as np
    from PIL import Image

    x = np.asarray(Image.open(a).convert("RGBA"), dtype=np.int16)
    y = np.asarray(Image.open(b).convert("RGBA"), dtype=np.int16)
    return float(np.abs(x - y).mean())


def report(frames: Path) -> None:
    """The table: per run (a ``NAME.json`` line beside a ``NAME/`` folder of frames), set-up,
    first render, renders/s after it, and the mean difference from the CPU's frames."""
    runs = {p.stem: json.loads(p.read_text().strip().splitlines()[-1]) for p in sorted(frames.glob("*.json"))}
    cpu = next((frames / name for name, run in runs.items() if run["device"] == "cpu"), None)
    print("| run | set-up s | first render s | renders/s after it | whole loop s | vs CPU: mean abs diff (8-bit) |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for name, run in runs.items():
        rate = (run["n"] - 1) / max(run["loop"] - run["first"], 1e-9)
        diff = "–"
        if cpu is not None and frames / name != cpu:
            pairs = [(p, cpu / p.name) for p in sorted((frames / name).glob("*.png")) if (cpu / p.name).exists()]
            if pairs:
                diffs = [mean_difference(a, b) for a, b in pairs]
                diff = f"{sum(diffs) / len(diffs):.2f} (max {max(diffs):.2f}, {len(pairs)} frames)"
        print(f"| {name} | {run['setup']:.1f} | {run['first']:.2f} | {rate:.1f} | {run['loop']:.1f} | {diff} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="step", required=True)
    sub.add_parser("prepare").add_argument("folder", type=Path)
    sub.add_parser("report").add_argument("frames", type=Path)
    args = parser.parse_args()
    if args.step == "prepare":
        prepare(args.folder)
    else:
        report(args.frames)


if __name__ == "__main__":
    main()
