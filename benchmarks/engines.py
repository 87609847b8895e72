"""Cycles against Mitsuba on the quickstart's scenes: does a verdict survive another renderer?

Runs the quickstart's rendered configurations (5 objects × 4 environments × its yaws and camera
heights; its blur left out: one image per render) at the model's framing (224² crop of 256²,
4 samples + OpenImageDenoise) once with ``[render] engine = "cycles"`` and once with
``"mitsuba"``, each in a fresh store, and prints per environment and per object: how often the
model's verdict (correct or not) agrees between the engines, Cohen's κ, how often its top-1 class
agrees, the PSNR of the Mitsuba image against the Cycles one, and the median seconds per render
(the renders table's, a worker's whole job); then each image whose verdict differs, with the
margin of each (the true class's probability minus the best other's, from the top 5). The machine may be shared: say so next to figures.

    .venv/bin/python benchmarks/engines.py [--samples-per-dim 6] [--rounds 2] [--keep DIR]

With ``--rounds 2`` each engine runs twice, alternated (cycles, mitsuba, mitsuba, cycles), each run in a
fresh store: the ratio of their per-render medians is the figure. Dr.Jit's kernel cache (``~/.drjit``)
is kept between runs, as on a user's machine after its first Mitsuba run.
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import tomlkit

REPO = Path(__file__).resolve().parents[1]
ENGINES = ("cycles", "mitsuba")
KEYS = ("object", "environment", "orientation_yaw", "camera_elevation")


def derived_spec(folder: Path, engine: str, samples_per_dim: int) -> Path:
    """The quickstart with ``engine``, its own store in ``folder`` and no post-processing."""
    doc = tomlkit.parse((REPO / "specs" / "quickstart.toml").read_text())
    doc["experiment"]["store"] = str(folder / f"store-{engine}")
    doc["experiment"]["name"] = f"quickstart-{engine}"
    doc["render"]["engine"] = engine
    kept = tomlkit.aot()
    for control in doc["controls"]:
        if control["type"] != "blur":
            kept.append(control)
    doc["controls"] = kept
    doc["policy"]["samples_per_dim"] = samples_per_dim
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"quickstart-{engine}.toml"
    path.write_text(tomlkit.dumps(doc))
    return path


def load_average() -> str:
    """The 1-, 5- and 15-minute load averages (the machine's load, said beside every figure)."""
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "unknown"


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return math.inf if mse == 0 else 10.0 * math.log10(255.0**2 / mse)


def kappa(pairs: list[tuple[bool, bool]]) -> float:
    """Cohen's κ of two verdicts per image (nan when one source says one thing only)."""
    n = len(pairs)
    observed = sum(a == b for a, b in pairs) / n
    pa, pb = sum(a for a, _ in pairs) / n, sum(b for _, b in pairs) / n
    chance = pa * pb + (1 - pa) * (1 - pb)
    return float("nan") if chance == 1 else (observed - chance) / (1 - chance)


def margin(row: dict) -> float:
    """The true class's probability minus the best other class's among the top k (negative: wrong)."""
    labels = set(row["label_ids"] or [])
    others = [p for c, p in zip(row["topk"], row["topk_probs"]) if c not in labels]
    return float(row["label_prob"]) - (max(others) if others else 0.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples-per-dim", type=int, default=6, help="yaws per turn (the quickstart's 6)")
    parser.add_argument("--keep", type=Path, help="keep the stores in this folder (default: a temporary one)")
    parser.add_argument("--rounds", type=int, default=1,
                        help="runs per engine, alternated (cycles, mitsuba, mitsuba, cycles, …), each in a fresh store")
    args = parser.parse_args()
    from PIL import Image

    from sweep3d.api import load
    from sweep3d.cache.store import Store

    folder = args.keep or Path(tempfile.mkdtemp(prefix="engines-"))
    folder.mkdir(parents=True, exist_ok=True)
    rows: dict[str, dict] = {}
    seconds: dict[str, list[float]] = defaultdict(list)
    wall: dict[str, list[float]] = defaultdict(list)
    print(f"load average before: {load_average()}")
    for round_ in range(args.rounds):
        for engine in (ENGINES if round_ % 2 == 0 else ENGINES[::-1]):
            experiment = load(derived_spec(folder / f"round{round_}", engine, args.samples_per_dim))
            started = time.perf_counter()
            experiment.run(progress=False)
            wall[engine].append(time.perf_counter() - started)
            store = Store(experiment.store)
            took = [r["seconds"] for r in store.table("renders").to_pylist()]
            seconds[engine].append(statistics.median(took))
            print(f"round {round_} {engine:8s} {seconds[engine][-1]:.3f} s per render (median of {len(took)}), "
                  f"whole run {wall[engine][-1]:.0f} s", flush=True)
            if engine not in rows:  # the verdicts of each engine's first run
                rows[engine] = {tuple(r[k] for k in KEYS): r for r in experiment.results().to_pylist()}
                rows[engine]["__store__"] = store  # type: ignore[assignment]
    print(f"load average after: {load_average()}")
    stores = {e: rows[e].pop("__store__") for e in ENGINES}
    shared = sorted(set(rows["cycles"]) & set(rows["mitsuba"]), key=str)
    groups: dict[str, list] = defaultdict(list)
    for key in shared:
        c, m = rows["cycles"][key], rows["mitsuba"][key]
        images = [np.asarray(Image.open(stores[e].blob_path(r["render_key"])).convert("RGB"))
                  for e, r in (("cycles", c), ("mitsuba", m))]
        entry = (bool(c["correct"]), bool(m["correct"]), c.get("top1_label") == m.get("top1_label"),
                 psnr(*images))
        for group in ("all", f"env {key[1]}", f"object {key[0]}"):
            groups[group].append(entry)
    print(f"{len(shared)} images per engine; the model's verdict and top-1 class, Mitsuba against Cycles")
    print(f"{'group':24s} {'n':>4s} {'verdicts agree':>15s} {'kappa':>6s} {'top-1 agrees':>13s} "
          f"{'acc cycles':>10s} {'acc mitsuba':>11s} {'PSNR dB (median)':>17s}")
    for group, entries in sorted(groups.items(), key=lambda kv: (kv[0] != "all", kv[0])):
        n = len(entries)
        agree = sum(a == b for a, b, _, _ in entries) / n
        top1 = sum(t for _, _, t, _ in entries) / n
        k = kappa([(a, b) for a, b, _, _ in entries])
        print(f"{group:24s} {n:4d} {agree:15.1%} {k:6.2f} {top1:13.1%} {sum(a for a, *_ in entries) / n:10.1%} "
              f"{sum(b for _, b, *_ in entries) / n:11.1%} {statistics.median(p for *_, p in entries):17.1f}")
    flips = [(key, rows["cycles"][key], rows["mitsuba"][key]) for key in shared
             if rows["cycles"][key]["correct"] != rows["mitsuba"][key]["correct"]]
    near = sum(abs(margin(c)) < 0.1 for _, c, _ in flips)
    print(f"{len(flips)} verdicts differ; {near} of them within 0.1 of a tie under Cycles (|margin| < 0.1):")
    for key, c, m in flips:
        print(f"  {key[0]:14s} {key[1]:7s} yaw {key[2]:6.0f} elevation {key[3]:3.0f}: Cycles {c['top1_label']!r} "
              f"(margin {margin(c):+.2f}), Mitsuba {m['top1_label']!r} (margin {margin(m):+.2f})")
    for engine in ENGINES:
        print(f"{engine:8s} {statistics.median(seconds[engine]):.3f} s per render (median over {len(seconds[engine])} "
              f"runs of each run's median); whole runs {', '.join(f'{w:.0f}' for w in wall[engine])} s")
    ratio = statistics.median(seconds["mitsuba"]) / statistics.median(seconds["cycles"])
    print(f"mitsuba / cycles per render: {ratio:.2f}")
    print(f"stores: {folder}")


if __name__ == "__main__":
    main()
