"""Overlapped stages and fast inference (the speed issue), measured in one run, printed as tables.

1. Inference per image at the quickstart's batch size (32 images at the model's 224² input), each
   way in turn for a few rounds (medians): torch eager, channels-last, ``torch.compile``
   (``--compile``: compiling alone takes minutes here), ONNX Runtime, and ONNX Runtime standing
   in for torch (the default: near ties go through torch), at 1 and 2 threads.
2. The quickstart from a cold store under each configuration: run wall against its own render
   stage, with the keys, labels and accuracy each gives (they must be the same for all).

    .venv/bin/python benchmarks/overlap.py [--configs overlap sequential-torch] [--objects 5] [--rounds 3]

Configurations: ``sequential-torch`` (the stages one after the other, torch eager: how runs went
before), ``sequential`` (one after the other, the default backend), ``overlap`` (the default),
``overlap-t1`` / ``overlap-t2`` (overlapped, ``[model] threads`` 1 or 2).
"""

from __future__ import annotations

import argparse
import copy
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np
from rich.console import Console
from rich.table import Table

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

BATCH = 32
CONFIGS = {  # name: (overlap, lines added under [model])
    "sequential-torch": (False, 'backend = "torch"\n'),
    "sequential": (False, ""),
    "overlap": (True, ""),
    "overlap-t1": (True, "threads = 1\n"),
    "overlap-t2": (True, "threads = 2\n"),
}


def photos() -> list[np.ndarray]:
    """32 natural images (scikit-image's photographs, each as is, mirrored, flipped and turned):
    random pixels would make near ties, and so torch fallbacks, far more common than in renders."""
    from skimage import data

    names = ("astronaut", "coffee", "chelsea", "rocket", "hubble_deep_field", "immunohistochemistry", "retina",
             "colorwheel")
    out = []
    for name in names:
        image = getattr(data, name)()[..., :3].astype(np.float32) / 255.0
        out += [image, image[:, ::-1], image[::-1], np.rot90(image)]
    return [np.ascontiguousarray(image) for image in out[:BATCH]]


def inference_ways(compile_too: bool, folder: Path) -> tuple[dict[str, tuple[int, Callable[[], Callable[[], object]]]],
                                                             list]:
    """Each way to infer a batch of 32: (torch threads, a set-up returning the call to time); and
    the ONNX runners made, once set up (to count the images the stand-in ran through torch)."""
    import torch

    from sweep3d.stages.infer.models import load_model
    from sweep3d.stages.infer.onnx_backend import OnnxRunner

    model = load_model("efficientnet-lite0")
    batch = torch.cat([model.preprocess(photo[None]) for photo in photos()])  # the model's 224² input
    channels_last = copy.deepcopy(model.module).to(memory_format=torch.channels_last)
    batch_cl = batch.contiguous(memory_format=torch.channels_last)

    def onnx(threads: int, exact_ranks: int | None) -> Callable[[], Callable[[], object]]:
        def setup() -> Callable[[], object]:
            runner = OnnxRunner(model, folder, "lite0", threads, exact_ranks)  # exported once, checked each time
            runners.append(runner)
            return lambda: runner(batch)
        return setup

    runners: list[OnnxRunner] = []

    ways: dict[str, tuple[int, Callable[[], Callable[[], object]]]] = {}
    for n in (1, 2):
        ways[f"torch eager, {n} thread(s)"] = (n, lambda: lambda: model.module(batch))
        ways[f"torch channels-last, {n} thread(s)"] = (n, lambda: lambda: channels_last(batch_cl))
        ways[f"ONNX Runtime, {n} thread(s)"] = (1, onnx(n, None))  # torch keeps one thread, as in a run
        ways[f"ONNX Runtime standing in for torch, {n} thread(s)"] = (1, onnx(n, 5))
    if compile_too:
        compiled = torch.compile(model.module)
        ways["torch.compile, 2 threads"] = (2, lambda: lambda: compiled(batch))
    return ways, runners


def measure_inference(rounds: int, compile_too: bool, folder: Path) -> tuple[dict[str, tuple[float, float]], int]:
    """Per way: (median ms per image over ``rounds`` rounds, seconds of set-up and first batch);
    and how many of the batch's images the stand-in ran through torch."""
    import torch

    ways, runners = inference_ways(compile_too, folder)
    calls, setup = {}, {}
    with torch.inference_mode():
        for name, (threads, make) in ways.items():
            torch.set_num_threads(threads)
            started = time.perf_counter()
            calls[name] = make()
            calls[name]()  # the first batch (torch.compile compiles here)
            setup[name] = time.perf_counter() - started
        times: dict[str, list[float]] = {name: [] for name in ways}
        for _ in range(rounds):  # each way in turn, so a change of load hits all of them
            for name, call in calls.items():
                torch.set_num_threads(ways[name][0])
                started = time.perf_counter()
                call()
                times[name].append((time.perf_counter() - started) / BATCH * 1000)
    by_torch = max(r.by_torch for r in runners) // (rounds + 1)  # per batch (the stand-ins' counts)
    return {name: (statistics.median(times[name]), setup[name]) for name in ways}, by_torch


def cut_objects(text: str, keep: int) -> str:
    """The spec with only its first ``keep`` objects (objects come just before environments)."""
    head, *objects = text.split("[[objects]]")
    last, rest = objects[-1].split("[[environments]]", 1)
    objects[-1] = last
    return head + "".join("[[objects]]" + o for o in objects[:keep]) + "[[environments]]" + rest


def quickstart(folder: Path, config: str, objects: int) -> dict:
    """One cold-store run of the quickstart (cut to its first ``objects`` objects) under ``config``."""
    import sweep3d
    from sweep3d.cache.store import Store
    from sweep3d.results import connect
    from sweep3d.runner.pipeline import run
    from sweep3d.stages.infer import onnx_backend

    overlap, model_lines = CONFIGS[config]
    text = (REPO / "specs" / "quickstart.toml").read_text()
    text = re.sub(r'store\s*=\s*"[^"]*"', 'store = "store"', text, count=1)
    text = cut_objects(text.replace("[model]\n", "[model]\n" + model_lines), objects)
    folder.mkdir(parents=True)
    (folder / "quickstart.toml").write_text(text)
    runners: list = []
    runner_class = onnx_backend.OnnxRunner

    class Counted(runner_class):  # benchmark-only: count the images that went through torch
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            runners.append(self)

    onnx_backend.OnnxRunner = Counted
    try:
        started = time.perf_counter()
        result = run(sweep3d.load(folder / "quickstart.toml").spec, overlap=overlap)
        wall = time.perf_counter() - started
    finally:
        onnx_backend.OnnxRunner = runner_class
    assert result.failed == 0, result.outcomes
    rows = connect(Store(folder / "store"), "quickstart").execute(
        "SELECT job, render_key, image_key, pred_key, top1_label, correct FROM results ORDER BY job").fetchall()
    return {"wall": wall, "stages": {o.stage: o.seconds for o in result.outcomes}, "rows": rows,
            "by_torch": sum(r.by_torch for r in runners)}


def inference_table(results: dict[str, tuple[float, float]], by_torch: int) -> Table:
    table = Table(title=f"Inference per image, EfficientNet-Lite0, batches of {BATCH} photographs at 224² (medians)",
                  caption=f"standing in for torch, ONNX Runtime ran {by_torch} of the {BATCH} images through torch")
    for column in ("way", "ms / image", "vs torch eager 1 thread", "set-up + first batch (s)"):
        table.add_column(column, justify="left" if column == "way" else "right")
    base = results["torch eager, 1 thread(s)"][0]
    for name, (ms, setup) in sorted(results.items(), key=lambda kv: kv[1][0]):
        table.add_row(name, f"{ms:.1f}", f"{base / ms:.2f}×", f"{setup:.1f}")
    return table


def runs_table(runs: dict[str, dict], jobs: int) -> Table:
    table = Table(title=f"Quickstart from a cold store ({jobs} jobs)")
    for column in ("configuration", "run wall (s)", "render stage (s)", "wall / render", "infer stage (s)",
                   "accuracy", "via torch", "same keys and labels"):
        table.add_column(column, justify="left" if column == "configuration" else "right")
    first = next(iter(runs.values()))["rows"]
    for name, run in runs.items():
        rows = run["rows"]
        correct = sum(bool(r[5]) for r in rows)
        table.add_row(name, f"{run['wall']:.1f}", f"{run['stages']['render']:.1f}",
                      f"{run['wall'] / run['stages']['render']:.3f}", f"{run['stages']['infer']:.1f}",
                      f"{correct / len(rows):.1%} ({correct} of {len(rows)})", str(run["by_torch"]),
                      "yes" if rows == first else "NO")
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configs", nargs="*", default=["sequential-torch", "overlap"], choices=list(CONFIGS))
    parser.add_argument("--objects", type=int, default=5, help="keep the quickstart's first N objects")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of the inference measurement (0: skip it)")
    parser.add_argument("--compile", action="store_true", help="also torch.compile (minutes to compile)")
    args = parser.parse_args()
    console = Console(width=max(Console().width, 150))  # the tables are wide
    with tempfile.TemporaryDirectory(prefix="sweep3d-overlap-") as tmp:
        if args.rounds:
            console.print("inference ...")
            console.print(inference_table(*measure_inference(args.rounds, args.compile, Path(tmp))))
        runs = {}
        for i, config in enumerate(args.configs):  # a configuration named twice runs twice (A/B/A/B)
            name = config if config not in runs else f"{config} (#{args.configs[:i + 1].count(config)})"
            console.print(f"quickstart, {name} ...")
            runs[name] = quickstart(Path(tmp) / str(i), config, args.objects)
        if runs:
            console.print(runs_table(runs, len(next(iter(runs.values()))["rows"])))


if __name__ == "__main__":
    main()
