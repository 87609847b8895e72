"""The report at scale: file size and time-to-interactive in headless Chromium.

Builds a synthetic store of N results (jobs and predictions written as Parquet rows with
:meth:`Store.append`, one small textured PNG blob per image — test data shaped like a run's
output, not a stand-in for the renderer), writes the report, opens it in Chromium and prints
a table: file size, build time, time to interactive (navigation start until the explorer and
the figures on screen are drawn), time until every figure is drawn, and the time a click on a
heat-map cell takes to fill the gallery and redraw the heat map.

    .venv/bin/python benchmarks/report_scale.py [--results 1000 10000] [--repeat 3]

:func:`build_store` is also used by ``tests/test_report_scale.py`` (size bound, page works).
"""

from __future__ import annotations

import argparse
import hashlib
import io
import math
import statistics
import tempfile
import textwrap
import time
from functools import lru_cache
from pathlib import Path

import numpy as np
from PIL import Image

from sweep3d.cache.store import Store, utc_now

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


def build_store(folder: Path, results: int, seed: int = 0) -> Path:
    """Write a spec and a store holding ``results`` synthetic results; returns the spec's path.

    Accuracy depends on the object, the yaw (side views are hard), the blur, the elevation, and
    on one interaction (the orange at night), so every panel of the report has something to show.
    """
    from sweep3d.stages import load_spec
    from sweep3d.stages.infer.evaluators import ClassificationEvaluator
    from sweep3d.stages.infer.stage import predictions_schema

    folder.mkdir(parents=True, exist_ok=True)
    (folder / "cube.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scenes = len(OBJECTS) * len(ENVIRONMENTS)
    objects = "\n".join(f'[[objects]]\nname = "{n}"\nmesh = "cube.obj"\nlabels = ["{label}"]\n'
                        for n, (label, _, _) in OBJECTS.items())
    environments = "\n".join(f'[[environments]]\nname = "{n}"\ncolor = [{", ".join(map(str, c))}]\n'
                             for n, c in ENVIRONMENTS.items())
    spec = folder / "spec.toml"
    spec.write_text(SPEC.format(objects=objects, environments=environments, samples=math.ceil(results / scenes)))
    loaded = load_spec(spec)
    columns = [f"{c.id}_{p}" for c in loaded.controls for p in c.spaces]
    assert columns == ["orientation_yaw", "camera_elevation", "blur_sigma"], columns

    store = Store(loaded.store)
    rng = np.random.default_rng(seed)
    jobs, predictions = [], []
    for index in range(results):
        obj = list(OBJECTS)[index % len(OBJECTS)]
        env = list(ENVIRONMENTS)[(index // len(OBJECTS)) % len(ENVIRONMENTS)]
        yaw = float(rng.uniform(-180, 180))
        elevation = float(rng.choice([0, 30, 60]))
        sigma = float(rng.choice([0.0, 1.0, 2.0]))
        key = hashlib.sha256(f"{seed}-{index}".encode()).hexdigest()
        jobs.append({"experiment": loaded.name, "job": index, "object": obj, "environment": env,
                     "orientation_yaw": yaw, "camera_elevation": elevation, "blur_sigma": sigma,
                     "render_key": key, "image_key": key, "pred_key": key})
        predictions.append(_prediction(key, obj, env, yaw, elevation, sigma, rng))
        path = store.blob_path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(_image(obj, env, yaw, sigma, rng))
    import pyarrow as pa

    store.write_table_file(store.jobs_path(loaded.name), pa.Table.from_pylist(jobs))
    store.append("predictions", predictions, predictions_schema(ClassificationEvaluator()))
    now = utc_now()
    store.append("runs", [{
        "run_id": f"synthetic{seed}", "experiment": loaded.name, "spec_path": str(spec), "spec": spec.read_text(),
        "jobs": results, "started_at": now, "created_at": now, "seconds": 0.0,
        **{f"{stage}_{k}": v for stage in ("render", "postprocess", "infer")
           for k, v in (("total", results), ("cached", 0), ("computed", results), ("failed", 0))},
    }])
    return spec


def _prediction(key: str, obj: str, env: str, yaw: float, elevation: float, sigma: float,
                rng: np.random.Generator) -> dict:
    from sweep3d.stages.infer.labels import IMAGENET

    label, base, confusions = OBJECTS[obj]
    p = base * (1 - 0.35 * abs(math.sin(math.radians(yaw)))) * (1 - 0.15 * sigma) * (1 - elevation / 400)
    if obj == "orange" and env == "night":
        p *= 0.3
    correct = bool(rng.random() < p)
    names = [label, *confusions]
    if not correct:  # one confusion first, then the truth, then the others
        first = confusions[int(rng.integers(len(confusions)))]
        names = [first, label, *[c for c in confusions if c != first]]
    probs = sorted(rng.dirichlet(np.ones(len(names))).tolist(), reverse=True)
    label_prob = probs[names.index(label)]
    ids = [IMAGENET.index(name) for name in names]
    return {"pred_key": key, "image_key": key, "model": "efficientnet-lite0", "model_digest": "synthetic",
            "seconds": 0.01, "created_at": utc_now(), "valid": True, "correct": correct, "top1": ids[0],
            "top1_label": names[0], "topk": ids, "topk_labels": names, "topk_probs": probs,
            "label_prob": label_prob, "loss": -math.log(max(label_prob, 1e-9))}


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
    from playwright.sync_api import sync_playwright

    from sweep3d.report import write_report
    from sweep3d.stages import load_spec

    started = time.perf_counter()
    path = write_report(load_spec(spec))
    build = time.perf_counter() - started
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
    return {"size_mb": path.stat().st_size / 1e6, "build_s": build, "ready_s": statistics.median(ready),
            "drawn_s": statistics.median(drawn), "click_s": statistics.median(clicks)}


def main() -> None:
    from rich.console import Console
    from rich.table import Table

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    table = Table(title="sweep3d report at scale (headless Chromium)")
    for column in ("results", "file size", "report build", "time to interactive", "all figures drawn",
                   "cell click → gallery"):
        table.add_column(column, justify="right")
    for results in args.results:
        with tempfile.TemporaryDirectory() as tmp:
            spec = build_store(Path(tmp) / "run", results)
            m = measure(spec, args.repeat)
        table.add_row(f"{results:,}", f"{m['size_mb']:.1f} MB", f"{m['build_s']:.1f} s", f"{m['ready_s']:.2f} s",
                      f"{m['drawn_s']:.2f} s", f"{m['click_s'] * 1000:.0f} ms")
    Console().print(table)
    print(textwrap.dedent("""\
        time to interactive: navigation start until the explorer's heat map and the figures on screen are
        drawn (the rest are drawn as they come near, or one by one after that: "all figures drawn");
        medians over the loads. Report build: reading the store, thumbnails, figures, writing the file."""))


if __name__ == "__main__":
    main()
