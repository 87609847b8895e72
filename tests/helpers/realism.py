"""A synthetic run for the realism tests: red and blue objects a tiny user model classifies by
colour, its store with real PNG blobs, stand-ins for the kit's page tools, the agreement
expected by the textbook formulas, and the alignment page in a browser with a fake camera. Tests
import from here, never from one another."""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import types
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest
from typer.testing import CliRunner

from sweep3d.cache.blobs import sha256_bytes
from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.core.pixels import encode_png8
from sweep3d.results import connect
from sweep3d.results.agreement import VERDICT_SCHEMA, verdict_key
from sweep3d.spec.columns import MODELS_METADATA, PARAMETERS_METADATA
from tests.helpers import CHROMIUM, CHROMIUM_ARGS, spec_toml, watch_page, write_spec

T0 = datetime(2024, 1, 1, tzinfo=timezone.utc)
SIDE = 32
SPEC = spec_toml("realism", seed=5, model={"name": "realism_model:redblue", "batch_size": 4},
                 objects=(("apple", "cube.obj", ["red"]), ("plum", "cube.obj", ["blue"])),
                 environments=("white", "grey"), body="""\
[[controls]]
type = "orientation"
yaw = [0, 90, 180]

[policy]
type = "grid"
""")

#: Red if the image's mean red exceeds its mean blue, else blue: logits ±20·(r − b) on pixels in [0, 1].
MODEL = '''
import torch
from sweep3d.stages.infer import Classifier, Preprocess


class RedBlue(torch.nn.Module):
    def forward(self, x):
        d = x[:, 0].mean(dim=(1, 2)) - x[:, 2].mean(dim=(1, 2))
        return torch.stack([20 * d, -20 * d], dim=1)


def redblue():
    return Classifier(RedBlue().eval(), Preprocess(resize=32, crop=32, mean=(0.0, 0.0, 0.0), std=(1.0, 1.0, 1.0)),
                      labels=["red", "blue"])
'''
LABELS = {"apple": "red", "plum": "blue"}
YAWS = (0, 90, 180)
ENVIRONMENTS = ("white", "grey")


def job_colours(seed: int = 0, repeat: int = 3) -> list[dict[str, Any]]:
    """Jobs (object × environment × yaw × ``repeat``) with a flat colour each: red and blue means a
    few levels to tens of levels apart, either way round."""
    rng = np.random.default_rng(seed)
    jobs = []
    for obj in LABELS:
        for env in ENVIRONMENTS:
            for yaw in YAWS:
                for _ in range(repeat):
                    r = int(rng.integers(60, 200))
                    b = int(np.clip(r + rng.choice([-1, 1]) * rng.integers(2, 40), 0, 255))
                    jobs.append({"object": obj, "environment": env, "orientation_yaw": yaw,
                                 "rgb": (r, int(rng.integers(0, 255)), b)})
    return jobs


def image_of(rgb: tuple[int, int, int]) -> np.ndarray:
    return np.broadcast_to(np.array(rgb, dtype=np.uint8), (SIDE, SIDE, 3)).copy()


def redblue_row(pixels: np.ndarray, label: str) -> dict[str, Any]:
    """What the test model's classification row says about ``pixels`` (8-bit), by numpy."""
    x = pixels.astype(np.float32) / np.float32(255.0)
    d = float(x[..., 0].mean() - x[..., 2].mean())
    logits = np.array([20 * d, -20 * d])
    p = np.exp(logits - logits.max())
    p /= p.sum()
    order = [0, 1] if logits[0] >= logits[1] else [1, 0]
    names = ["red", "blue"]
    truth = names.index(label)
    return {"valid": True, "correct": order[0] == truth, "top1": order[0], "top1_label": names[order[0]],
            "topk": order, "topk_labels": [names[i] for i in order], "topk_probs": [float(p[i]) for i in order],
            "label_prob": float(p[truth]), "loss": float(-math.log(p[truth])), "correct_top5": True,
            "label_ids": [truth]}


def make_run(folder: Path, jobs: list[dict[str, Any]] | None = None,
             rows: list[dict[str, Any]] | None = None) -> Path:
    """A spec, its model module and a store as a finished run leaves them: a jobs file, image rows
    with their PNG blobs, and predictions (``rows``: each job's prediction row; default the test
    model's answer on its image). Returns the spec's path."""
    (folder / "realism_model.py").write_text(MODEL)
    spec = write_spec(folder, SPEC)
    jobs = job_colours() if jobs is None else jobs
    store = Store(folder / "store")
    plan, images, predictions = [], [], []
    for i, job in enumerate(jobs):
        pixels = image_of(job["rgb"])
        data = encode_png8(pixels)
        key = f"{i:04x}" + "ab" * 30
        store.blob_path(key).parent.mkdir(parents=True, exist_ok=True)
        store.blob_path(key).write_bytes(data)
        plan.append({"experiment": "realism", "job": i, "object": job["object"], "environment": job["environment"],
                     "orientation_yaw": float(job["orientation_yaw"]), "render_key": key, "image_key": key,
                     "pred_key": f"p{key}", "model": "realism_model:redblue"})
        images.append({"image_key": key, "render_key": key, "valid": True, "seconds": 0.0, "created_at": T0,
                       "sha256": sha256_bytes(data)})
        row = redblue_row(pixels, LABELS[job["object"]]) if rows is None else rows[i]
        predictions.append({"pred_key": f"p{key}", "image_key": key, "model": "realism_model:redblue",
                            "model_digest": "d", "seconds": 0.0, "created_at": T0, **row})
    table = pa.Table.from_pylist(plan).replace_schema_metadata(
        {PARAMETERS_METADATA: json.dumps(["orientation_yaw"]).encode(),
         MODELS_METADATA: json.dumps(["realism_model:redblue"]).encode()})
    store.write_table_file(store.jobs_path("realism"), table)
    store.append("images", images)
    store.append("predictions", predictions)
    return spec



# -- a run with 2D controls, its renders planted and the rest computed by sweep3d's own stages ---
POST_YAWS = tuple(range(0, 360, 30))
POST_SPEC = spec_toml("realism", seed=5, model={"name": "sharp_model:sharp", "batch_size": 8},
                      objects=(("apple", "cube.obj", ["red"]), ("plum", "cube.obj", ["blue"])),
                      environments=("white", "grey"), body=f"""\
[[controls]]
type = "orientation"
yaw = {list(POST_YAWS)}

[[controls]]
type = "blur"
sigma = [0.0, 1.5]

[[controls]]
type = "noise"
std = [0.0, 0.05]

[policy]
type = "grid"

[postprocess]
store = "all"
""")

#: "red" when the image is sharp: the mean squared step between neighbouring pixels of its red
#: channel above 0.006 (a log-odds of 10 per e-fold). Blur lowers that energy and noise raises
#: it, so a 2D control applied twice moves verdicts that applying it once did not.
SHARP_MODEL = '''
import torch
from sweep3d.stages.infer import Classifier, Preprocess


class Sharp(torch.nn.Module):
    def forward(self, x):
        energy = (x[:, 0, :, 1:] - x[:, 0, :, :-1]).pow(2).mean(dim=(1, 2))
        d = 10 * (torch.log(energy + 1e-6) - torch.log(torch.tensor(0.006)))
        return torch.stack([d, -d], dim=1)


def sharp():
    return Classifier(Sharp().eval(), Preprocess(resize=32, crop=32, mean=(0.0, 0.0, 0.0), std=(1.0, 1.0, 1.0)),
                      labels=["red", "blue"])
'''


def stripes(amplitude: int) -> np.ndarray:
    """A render: red stripes four pixels wide, ``amplitude`` levels over a level of 100, on grey."""
    pixels = np.full((SIDE, SIDE, 3), 100, np.uint8)
    pixels[..., 0] += ((np.arange(SIDE) // 4 % 2) * amplitude).astype(np.uint8)
    return pixels


def make_post_run(folder: Path) -> Path:
    """A finished run of :data:`POST_SPEC` (blur and noise as 2D controls) without Blender: each
    planned render is planted in the store (stripes of amplitudes spread geometrically from 10 to
    150 levels), then ``sweep3d run`` post-processes, stores the images and classifies them with
    :data:`SHARP_MODEL` through its own stages. Apple and plum share every render (one mesh), so
    each image is right for one of them. Returns the spec's path."""
    from sweep3d.runner import plan_spec
    from tests.helpers import load_spec

    (folder / "sharp_model.py").write_text(SHARP_MODEL)
    spec = write_spec(folder, POST_SPEC)
    keys = list(dict.fromkeys(job.render_key for job in plan_spec(load_spec(spec)).jobs))
    store = Store(folder / "store")
    rows = []
    for i, key in enumerate(keys):
        data = encode_png8(stripes(round(10 * 15 ** (i / (len(keys) - 1)))))
        store.blob_path(key).parent.mkdir(parents=True, exist_ok=True)
        store.blob_path(key).write_bytes(data)
        rows.append({"render_key": key, "width": SIDE, "height": SIDE, "valid": True, "seconds": 0.1,
                     "created_at": T0, "sha256": sha256_bytes(data)})
    store.append("renders", rows)
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output
    return spec

@dataclasses.dataclass(frozen=True)
class StubShot:
    job_id: str
    render: str
    edges: str
    caption: str


def stub_kit_tools(monkeypatch: pytest.MonkeyPatch) -> list[list[StubShot]]:
    """Stand-ins for ``sweep3d.followups.realism.edges`` and ``.align`` (built elsewhere); returns the
    shots each ``write_align_page`` call got."""
    calls: list[list[StubShot]] = []

    def edge_image(rgb: np.ndarray) -> np.ndarray:
        grey = rgb.astype(np.float32).mean(axis=2)
        edge = np.abs(np.diff(grey, axis=1, prepend=grey[:, :1])) > 8
        out = np.zeros((*rgb.shape[:2], 4), np.uint8)
        out[edge] = (255, 0, 255, 255)
        return out

    def write_align_page(kit_dir: Path, shots) -> Path:
        calls.append(list(shots))
        page = kit_dir / "align.html"
        page.write_text("".join(f"<img src='{s.render}'><img src='{s.edges}'>{s.job_id}\n" for s in shots))
        return page

    monkeypatch.setitem(sys.modules, "sweep3d.followups.realism.edges", types.SimpleNamespace(edge_image=edge_image))
    monkeypatch.setitem(sys.modules, "sweep3d.followups.realism.align",
                        types.SimpleNamespace(AlignShot=StubShot, write_align_page=write_align_page))
    return calls


def kit_files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def pick(spec: Path, out: Path, *extra: str) -> Any:
    result = CliRunner().invoke(app, ["realism", "pick", str(spec), "-o", str(out), *extra])
    return result


T1 = datetime(2024, 2, 1, tzinfo=timezone.utc)


def verdict(job: int, correct: bool, source: str = "photo", at: datetime = T1, valid: bool = True) -> dict[str, Any]:
    row = {name: None for name in VERDICT_SCHEMA.names}
    row.update(verdict_key=verdict_key(source, "realism", job, "realism_model:redblue"), source=source,
               experiment="realism", job=job, model="realism_model:redblue", valid=valid,
               correct=correct,
               top1_label="red" if correct else "blue", created_at=at)
    return row


def hand(pairs: list[tuple[bool, bool]]) -> dict[str, Any]:
    """Agreement, PPV, NPV and κ of (simulation, source) verdicts, by the textbook formulas."""
    n = len(pairs)
    agree = sum(a == b for a, b in pairs)
    sim_right = [b for a, b in pairs if a]
    sim_wrong = [b for a, b in pairs if not a]
    p_sim = sum(a for a, _ in pairs) / n
    p_src = sum(b for _, b in pairs) / n
    expected = p_sim * p_src + (1 - p_sim) * (1 - p_src)
    return {"n": n, "n_agree": agree, "agreement": agree / n,
            "ppv": sum(sim_right) / len(sim_right) if sim_right else None,
            "npv": sum(not b for b in sim_wrong) / len(sim_wrong) if sim_wrong else None,
            "kappa": None if expected == 1 else (agree / n - expected) / (1 - expected)}


def agreement_rows(folder: Path, experiment: str = "realism") -> list[dict[str, Any]]:
    con = connect(Store(folder / "store"), experiment)
    cursor = con.execute("SELECT * FROM agreement")
    names = [d[0] for d in cursor.description]
    return [dict(zip(names, r)) for r in cursor.fetchall()]


def sim_verdicts() -> list[bool]:
    return [redblue_row(image_of(j["rgb"]), LABELS[j["object"]])["correct"] for j in job_colours()]


# -- the alignment page in a browser with a fake camera ----------------------------------------
def write_y4m(path: Path, rgb: np.ndarray, frames: int = 3) -> Path:
    """A YUV4MPEG2 file of ``frames`` copies of ``rgb``: a text header, then per frame ``FRAME`` and
    the planes Y, U, V (4:2:0: chroma at half width and height), BT.601 studio range."""
    h, w, _ = rgb.shape
    r, g, b = (rgb[..., i].astype(np.float64) for i in range(3))
    y = 16 + (65.481 * r + 128.553 * g + 24.966 * b) / 255
    u = 128 + (-37.797 * r - 74.203 * g + 112.0 * b) / 255
    v = 128 + (112.0 * r - 93.786 * g - 18.214 * b) / 255
    half = [c.reshape(h // 2, 2, w // 2, 2).mean(axis=(1, 3)) for c in (u, v)]
    planes = b"".join(np.clip(np.round(p), 0, 255).astype(np.uint8).tobytes() for p in (y, *half))
    path.write_bytes(f"YUV4MPEG2 W{w} H{h} F30:1 Ip A1:1 C420jpeg\n".encode() + b"FRAME\n".join([b""] + [planes] * frames))
    return path


@contextmanager
def open_align(browser: Any, page_path: Path, width: int = 400, height: int = 700,
               init_script: str | None = None) -> Iterator[tuple[Any, dict[str, list]]]:
    """``align.html`` in a fresh context of ``browser`` (a phone-sized viewport by default), once
    its camera (or the fallback) is set up; its errors, requests and dialogs collected."""
    context = browser.new_context(viewport={"width": width, "height": height}, accept_downloads=True)
    try:
        page = context.new_page()
        events = watch_page(page)
        if init_script:
            page.add_init_script(init_script)
        page.goto(page_path.as_uri())
        page.wait_for_function("() => document.documentElement.dataset.ready === '1'", timeout=30_000)
        yield page, events
    finally:
        context.close()


@contextmanager
def fake_camera(chromium: Any, video: Path) -> Iterator[Any]:
    """A second headless Chromium (from the ``chromium`` fixture's Playwright) whose camera is a
    fake device playing ``video`` (a ``.y4m`` file, :func:`write_y4m`), granted without asking."""
    browser = chromium.browser_type.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS + [
        "--use-fake-device-for-media-stream", "--use-fake-ui-for-media-stream",
        f"--use-file-for-fake-video-capture={video}"])
    try:
        yield browser
    finally:
        browser.close()
