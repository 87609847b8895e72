"""The report at scale: file size and time-to-interactive in headless Chromium.

Builds a synthetic store of N results (jobs and predictions written in bulk as Parquet
columns, a small textured PNG blob for each image the report embeds — test data shaped like a
run's output, not a stand-in for the renderer), writes the report, opens it in Chromium and
prints a table: file size, the explorer's joint-table cells and the images embedded, build
time, time to interactive (navigation start until the explorer and the figures on screen are
drawn), time until every figure is drawn, and the time a click on a heat-map cell takes to
fill the gallery and redraw the heat map.

    .venv/bin/python benchmarks/report_scale.py [--results 10000 100000 1000000] [--repeat 3]

:func:`build_store` is also used by the report's tests (``tests/test_report_scale.py``,
``tests/test_report_explorer.py``).
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import math
import re
import statistics
import tempfile
import textwrap
import time
from functools import lru_cache
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
from PIL import Image

from sweep3d.cache.store import Store, segment_name, utc_now
from sweep3d.report import image_keys
from sweep3d.spec.columns import PARAMETERS_METADATA

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-sync"]
OBJECTS = {  # name -> (ImageNet label, base accuracy, what it is taken for)
    "soccer": ("soccer ball", 0.95, ["volleyball", "rugby ball"]),
    "basketball": ("basketball", 0.85, ["volleyball", "soccer ball"]),
    "camera": ("reflex camera", 0.75, ["binoculars", "Polaroid camera"]),
    "toaster": ("toaster", 0.55, ["electrical switch", "radiator", "space heater"]),
    "orange": ("orange", 0.35, ["ping-pong ball", "lemon"]),
}
ENVIRONMENTS = {"studio": (0.85, 0.85, 0.85), "forest": (0.25, 0.45, 0.2), "city": (0.55, 0.55, 0.6),
                "night": (0.05, 0.05, 0.12)}
IMAGE_SIZE = 96
TOP_K = 3  # the truth and two confusions

SPEC = """\
[experiment]
name = "scale"
seed = 0
store = "store"

[model]
name = "efficientnet-lite0"

{objects}
{environments}
[[controls]]
type = "orientation"
yaw = {{ range = [-180, 180] }}

[[controls]]
type = "camera"
elevation = [0, 30, 60]

[[controls]]
type = "blur"
sigma = [0.0, 1.0, 2.0]

[policy]
type = "random"
samples = {samples}
"""


def build_store(folder: Path, results: int, seed: int = 0, images: bool = True) -> Path:
    """Write a spec and a store holding ``results`` synthetic results; returns the spec's path.

    Rows are written in bulk (one jobs file, one predictions segment, as a compacted store holds
    them); image blobs only for the images the report embeds (:func:`sweep3d.report.image_keys`),
    since writing a PNG per result would dominate at 10^6. Accuracy depends on the object, the
    yaw (side views are hard), the blur, the elevation, and on one interaction (the orange at
    night), so every panel of the report has something to show; one result in 500 is invalid.
    ``images=False`` writes no blob (for tests of numbers only).
    """
    from sweep3d.stages import load_spec

    spec = write_spec(folder, results)
    loaded = load_spec(spec)
    assert loaded.parameter_columns == ["orientation_yaw", "camera_elevation", "blur_sigma"], loaded.parameter_columns
    store = Store(loaded.store)
    jobs, predictions = synthetic_tables(loaded.name, results, seed)
    store.write_table_file(store.jobs_path(loaded.name), jobs.replace_schema_metadata(
        {PARAMETERS_METADATA: json.dumps(loaded.parameter_columns).encode()}))
    store.write_table_file(store.table_dir("predictions") / segment_name(), predictions)
    now = utc_now()
    store.append("runs", [{
        "run_id": f"synthetic{seed}", "experiment": loaded.name, "spec_path": str(spec), "spec": spec.read_text(),
        "jobs": results, "started_at": now, "created_at": now, "seconds": 0.0,
        **{f"{stage}_{k}": v for stage in ("render", "postprocess", "infer")
           for k, v in (("total", results), ("cached", 0), ("computed", results), ("failed", 0))},
    }])
    if images:
        write_images(store, jobs, image_keys(loaded))
    return spec


def write_spec(folder: Path, results: int) -> Path:
    """The benchmark's spec (5 objects × 4 environments, random yaw, 3 elevations, 3 blurs)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "cube.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scenes = len(OBJECTS) * len(ENVIRONMENTS)
    objects = "\n".join(f'[[objects]]\nname = "{n}"\nmesh = "cube.obj"\nlabels = ["{label}"]\n'
                        for n, (label, _, _) in OBJECTS.items())
    environments = "\n".join(f'[[environments]]\nname = "{n}"\ncolor = [{", ".join(map(str, c))}]\n'
                             for n, c in ENVIRONMENTS.items())
    spec = folder / "spec.toml"
    spec.write_text(SPEC.format(objects=objects, environments=environments, samples=math.ceil(results / scenes)))
    return spec


def synthetic_tables(experiment: str, results: int, seed: int) -> tuple[pa.Table, pa.Table]:
    """The jobs table and the predictions table of ``results`` synthetic results, built column-wise."""
    from sweep3d.stages.infer.evaluators import ClassificationEvaluator
    from sweep3d.stages.infer.stage import predictions_schema

    rng = np.random.default_rng(seed)
    index = np.arange(results)
    obj, env = index % len(OBJECTS), (index // len(OBJECTS)) % len(ENVIRONMENTS)
    yaw = rng.uniform(-180, 180, results)
    elevation = rng.choice([0.0, 30.0, 60.0], results)
    sigma = rng.choice([0.0, 1.0, 2.0], results)
    base = np.array([accuracy for _, accuracy, _ in OBJECTS.values()])[obj]
    p = base * (1 - 0.35 * np.abs(np.sin(np.radians(yaw)))) * (1 - 0.15 * sigma) * (1 - elevation / 400)
    p = np.where((obj == list(OBJECTS).index("orange")) & (env == list(ENVIRONMENTS).index("night")), p * 0.3, p)
    correct = rng.random(results) < p
    valid = rng.random(results) >= 1 / 500
    keys = pa.array([hashlib.sha256(f"{seed}-{i}".encode()).hexdigest() for i in range(results)])
    jobs = pa.table({
        "experiment": pa.array([experiment] * results), "job": pa.array(index, pa.int64()),
        "object": pa.array(np.array(list(OBJECTS))[obj]), "environment": pa.array(np.array(list(ENVIRONMENTS))[env]),
        "orientation_yaw": yaw, "camera_elevation": elevation, "blur_sigma": sigma,
        "render_key": keys, "image_key": keys, "pred_key": keys,
    })
    topk, probs = _topk(obj, correct, rng)
    truth = np.where(correct, topk[:, 0], topk[:, 1])  # the truth is first when correct, else second
    names = np.array(_label_names(), dtype=object)
    loss = -np.log(np.maximum(np.where(correct, probs[:, 0], probs[:, 1]), 1e-9))
    columns = {
        "pred_key": keys, "image_key": keys, "model": pa.array(["efficientnet-lite0"] * results),
        "model_digest": pa.array(["synthetic"] * results), "seconds": np.full(results, 0.01),
        "created_at": pa.array([utc_now().replace(tzinfo=None)] * results, pa.timestamp("us")),
        "valid": valid, "correct": pa.array(correct, mask=~valid), "top1": pa.array(topk[:, 0], mask=~valid),
        "top1_label": pa.array(names[topk[:, 0]], mask=~valid),
        "topk": _lists(topk, valid, pa.int32()), "topk_labels": _lists(names[topk], valid, pa.string()),
        "topk_probs": _lists(probs, valid, pa.float32()),
        "label_prob": pa.array(np.exp(-loss), mask=~valid), "loss": pa.array(loss, mask=~valid),
        "correct_top5": pa.array(correct | (topk[:, 1] == truth), mask=~valid),
        "label_ids": _lists(truth[:, None], valid, pa.int32()),
    }
    schema = predictions_schema(ClassificationEvaluator())
    return jobs, pa.table({name: columns[name] for name in schema.names}, schema=schema)


def _topk(obj: np.ndarray, correct: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Top-3 ImageNet ids and probabilities per result: the truth first when correct, else one of
    the object's confusions first and the truth second."""
    from sweep3d.stages.infer.labels import IMAGENET

    topk, probs = np.zeros((len(obj), TOP_K), np.int32), np.zeros((len(obj), TOP_K))
    for o, (label, _, confusions) in enumerate(OBJECTS.values()):
        rows = np.flatnonzero(obj == o)
        orders = [[label, *confusions]] + [[c, label, *[d for d in confusions if d != c]] for c in confusions]
        table = np.array([[IMAGENET.index(name) for name in order[:TOP_K]] for order in orders], np.int32)
        choice = np.where(correct[rows], 0, 1 + rng.integers(len(confusions), size=len(rows)))
        topk[rows] = table[choice]
        probs[rows] = -np.sort(-rng.dirichlet(np.ones(TOP_K + 1), size=len(rows))[:, :TOP_K], axis=1)
    return topk, probs


def _lists(values: np.ndarray, valid: np.ndarray, kind: pa.DataType) -> pa.Array:
    """Rows of ``values`` as a list column (null where not valid)."""
    width = values.shape[1]
    offsets = pa.array(np.arange(len(values) + 1, dtype=np.int32) * width, mask=np.append(~valid, False))
    return pa.ListArray.from_arrays(offsets, pa.array(values.reshape(-1), type=kind))


def _label_names() -> list[str]:
    """Class id → name, for the classes the synthetic model predicts (the names the spec uses)."""
    from sweep3d.stages.infer.labels import IMAGENET

    names = [""] * len(IMAGENET)
    for label, _, confusions in OBJECTS.values():
        for name in (label, *confusions):
            names[IMAGENET.index(name)] = name
    return names


def write_images(store: Store, jobs: pa.Table, keys: list[str]) -> None:
    """A small PNG blob for each of ``keys`` (drawn from its job's object, environment, yaw, blur)."""
    columns = jobs.select(["image_key", "object", "environment", "orientation_yaw", "blur_sigma"])
    for row in columns.filter(pc.is_in(jobs["image_key"], pa.array(keys, pa.string()))).to_pylist():
        rng = np.random.default_rng(int(row["image_key"][:8], 16))
        path = store.blob_path(row["image_key"])
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(_image(row["object"], row["environment"], row["orientation_yaw"], row["blur_sigma"], rng))


def _image(obj: str, env: str, yaw: float, sigma: float, rng: np.random.Generator) -> bytes:
    """A small PNG: the environment's colour, a lit disc in the object's colour, some noise."""
    y, x, backgrounds, noise = _canvas()
    hue = list(OBJECTS).index(obj) / len(OBJECTS)
    colour = np.array([0.5 + 0.5 * math.cos(2 * math.pi * (hue + k / 3)) for k in range(3)], dtype=np.float32)
    cx, r = 0.5 + 0.2 * math.sin(math.radians(yaw)), 0.28
    disc = ((x - cx) ** 2 + (y - 0.5) ** 2) < r * r
    shade = np.clip(1.1 - 1.5 * np.hypot(x - cx + 0.1, y - 0.4), 0.2, 1.0)[..., None]
    image = np.where(disc[..., None], colour * shade, backgrounds[env])
    image += noise[int(rng.integers(len(noise)))] * (1 + sigma / 2)
    buf = io.BytesIO()
    Image.fromarray((np.clip(image, 0, 1) * 255).astype(np.uint8), "RGB").save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


@lru_cache(maxsize=1)
def _canvas() -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], list[np.ndarray]]:
    """Pixel coordinates, each environment's background and a few noise fields, computed once."""
    y, x = (np.mgrid[0:IMAGE_SIZE, 0:IMAGE_SIZE] / IMAGE_SIZE).astype(np.float32)
    backgrounds = {name: (np.asarray(c, dtype=np.float32)[None, None, :] * (0.7 + 0.3 * y[..., None]))
                   for name, c in ENVIRONMENTS.items()}
    rng = np.random.default_rng(12345)
    noise = [rng.normal(0, 0.02, (IMAGE_SIZE, IMAGE_SIZE, 3)).astype(np.float32) for _ in range(16)]
    return y, x, backgrounds, noise


# -- measurement ------------------------------------------------------------------------------
CELL_CENTRE = """() => {
  const gd = document.getElementById('explorer-plot'), box = gd.getBoundingClientRect();
  const xa = gd._fullLayout.xaxis, ya = gd._fullLayout.yaxis;
  return [box.left + xa._offset + xa.l2p(0), box.top + ya._offset + ya.l2p(0)];
}"""


def measure(spec: Path, repeat: int) -> dict[str, float]:
    """Build the report of ``spec`` and time it in Chromium (medians over ``repeat`` fresh pages)."""
    from sweep3d.report import write_report
    from sweep3d.stages import load_spec

    started = time.perf_counter()
    path = write_report(load_spec(spec))
    build = time.perf_counter() - started
    html = path.read_text(encoding="utf-8")
    explorer = json.loads(re.search(r'id="explorer-data">(.*?)</script>', html, re.S).group(1))
    thumbs = json.loads(re.search(r'id="thumbs">(.*?)</script>', html, re.S).group(1))
    return {"size_mb": path.stat().st_size / 1e6, "cells": explorer["cells"], "images": sum(map(bool, thumbs)),
            "build_s": build, **browse(path, repeat)}


def browse(path: Path, repeat: int) -> dict[str, float]:
    """Medians over ``repeat`` fresh pages: time to interactive, every figure drawn, a cell click."""
    from playwright.sync_api import sync_playwright

    ready, drawn, clicks = [], [], []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            for _ in range(repeat):
                page = browser.new_page(viewport={"width": 1280, "height": 900})
                page.goto(path.as_uri())
                page.wait_for_function("() => document.documentElement.dataset.drawn === '1'", timeout=120_000)
                ready.append(page.evaluate("window.sweep3d.readyAt") / 1000)
                drawn.append(page.evaluate("window.sweep3d.drawnAt") / 1000)
                page.mouse.click(*page.evaluate(CELL_CENTRE))
                page.wait_for_function("() => window.sweep3d.explorer.timings.click !== undefined")
                clicks.append(page.evaluate("window.sweep3d.explorer.timings.click") / 1000)
                page.close()
        finally:
            browser.close()
    return {"ready_s": statistics.median(ready), "drawn_s": statistics.median(drawn),
            "click_s": statistics.median(clicks)}


def main() -> None:
    from rich.console import Console
    from rich.table import Table

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    table = Table(title="sweep3d report at scale (headless Chromium)")
    for column in ("results", "store written", "file size", "explorer cells", "images embedded", "report build",
                   "time to interactive", "all figures drawn", "cell click → gallery"):
        table.add_column(column, justify="right")
    for results in args.results:
        with tempfile.TemporaryDirectory() as tmp:
            started = time.perf_counter()
            spec = build_store(Path(tmp) / "run", results)
            written = time.perf_counter() - started
            m = measure(spec, args.repeat)
        table.add_row(f"{results:,}", f"{written:.0f} s", f"{m['size_mb']:.1f} MB", f"{m['cells']:,}",
                      f"{m['images']:,}", f"{m['build_s']:.1f} s", f"{m['ready_s']:.2f} s", f"{m['drawn_s']:.2f} s",
                      f"{m['click_s'] * 1000:.0f} ms")
    Console().print(table)
    print(textwrap.dedent("""\
        time to interactive: navigation start until the explorer's heat map and the figures on screen are
        drawn (the rest are drawn as they come near, or one by one after that: "all figures drawn");
        medians over the loads. Store written: rows in bulk, and the report's images (found by building
        its panels once). Report build: reading the store, the panels, the thumbnails, writing the file."""))


if __name__ == "__main__":
    main()
