"""``sweep3d realism pick``: half right and half wrong per object and model, seeded, spread over
environments and values, near ties left out, and a kit whose ``design.csv`` the table policy reads.

The store is synthetic (written row by row, with real PNG blobs): each job's image is a flat
colour whose red and blue means decide what the test model (``realism_model:redblue``, written
beside the spec) answers, so the verdicts stored here are the ones that model gives on them
(tests/test_realism_score.py runs it). The kit's edge images and alignment page come from
``sweep3d.realism.edges`` and ``sweep3d.realism.align``; the tests stand small stubs in for them
(:func:`stub_kit_tools`), so only what ``pick`` writes itself is checked here.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import sys
import types
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest
from PIL import Image
from typer.testing import CliRunner

from sweep3d.cache.blobs import sha256_bytes
from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.pixels import encode_png8
from sweep3d.realism.pick import margin, near_tie
from sweep3d.spec.columns import MODELS_METADATA, PARAMETERS_METADATA
from tests.conftest import write_spec

T0 = datetime(2024, 1, 1, tzinfo=timezone.utc)
SIDE = 32
SPEC = """\
[experiment]
name = "realism"
seed = 5
store = "store"

[render]
resolution = 32
samples = 1
denoise = false

[model]
name = "realism_model:redblue"
batch_size = 4

[[objects]]
name = "apple"
mesh = "cube.obj"
labels = ["red"]

[[objects]]
name = "plum"
mesh = "cube.obj"
labels = ["blue"]

[[environments]]
name = "white"
color = [1.0, 1.0, 1.0]

[[environments]]
name = "grey"
color = [0.5, 0.5, 0.5]

[[controls]]
type = "orientation"
yaw = [0, 90, 180]

[policy]
type = "grid"
"""

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


@dataclasses.dataclass(frozen=True)
class StubShot:
    job_id: str
    render: str
    edges: str
    caption: str


def stub_kit_tools(monkeypatch: pytest.MonkeyPatch) -> list[list[StubShot]]:
    """Stand-ins for ``sweep3d.realism.edges`` and ``.align`` (built elsewhere); returns the
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

    monkeypatch.setitem(sys.modules, "sweep3d.realism.edges", types.SimpleNamespace(edge_image=edge_image))
    monkeypatch.setitem(sys.modules, "sweep3d.realism.align",
                        types.SimpleNamespace(AlignShot=StubShot, write_align_page=write_align_page))
    return calls


def kit_files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def pick(spec: Path, out: Path, *extra: str) -> Any:
    result = CliRunner().invoke(app, ["realism", "pick", str(spec), "-o", str(out), *extra])
    return result


def test_margin_is_the_true_class_less_the_best_other() -> None:
    right = {"correct": True, "topk": [3, 1, 4], "topk_probs": [0.6, 0.3, 0.1], "label_prob": 0.6, "label_ids": [3]}
    wrong = {"correct": False, "topk": [1, 3], "topk_probs": [0.52, 0.47], "label_prob": 0.47, "label_ids": [3]}
    two_true = {"correct": True, "topk": [3, 4, 1], "topk_probs": [0.5, 0.3, 0.2], "label_prob": 0.8,
                "label_ids": [3, 4]}
    assert margin(right) == pytest.approx(0.3)
    assert margin(wrong) == pytest.approx(-0.05) and not near_tie(wrong)
    assert near_tie({**wrong, "topk_probs": [0.5, 0.47], "label_prob": 0.47})
    assert margin(two_true) == pytest.approx(0.6)  # the label set's probability against class 1
    assert margin({**right, "margin": -0.01}) == -0.01  # a stored margin column wins
    assert margin({"correct": True}) is None and not near_tie({"correct": True})


def test_pick_writes_a_deterministic_kit_half_right_half_wrong(tmp_path: Path, monkeypatch) -> None:
    spec = make_run(tmp_path)
    calls = stub_kit_tools(monkeypatch)
    result = pick(spec, tmp_path / "kit", "--per-object", "4")
    assert result.exit_code == 0, result.output
    kit = json.loads((tmp_path / "kit" / "kit.json").read_text())
    store = Store(tmp_path / "store")
    jobs = job_colours()
    for obj in LABELS:
        mine = [p for p in kit["picks"] if p["object"] == obj]
        assert sorted(p["correct"] for p in mine) == [False, False, True, True]
        for p in mine:  # the verdict the kit records is the store's
            assert p["correct"] == redblue_row(image_of(jobs[p["job"]]["rgb"]), LABELS[obj])["correct"]
        assert len({p["environment"] for p in mine}) == 2  # spread: both environments
        assert len({jobs[p["job"]]["orientation_yaw"] for p in mine}) == 3  # and every yaw
    assert kit["jobs"] == sorted({p["job"] for p in kit["picks"]})
    for job in kit["jobs"]:  # the render is the image the model saw, byte for byte; edges beside it
        key = f"{job:04x}" + "ab" * 30
        assert (tmp_path / "kit" / "renders" / f"{job}.png").read_bytes() == store.blob_path(key).read_bytes()
        with Image.open(tmp_path / "kit" / "edges" / f"{job}.png") as im:
            assert im.mode == "RGBA" and im.size == (SIDE, SIDE)
    assert [s.job_id for s in calls[0]] == [str(j) for j in kit["jobs"]]
    assert all(s.render == f"renders/{s.job_id}.png" and s.edges == f"edges/{s.job_id}.png" for s in calls[0])
    with (tmp_path / "kit" / "design.csv").open() as handle:
        design = list(csv.DictReader(handle))
    assert [(r["object"], r["environment"], float(r["orientation_yaw"])) for r in design] == [
        (jobs[j]["object"], jobs[j]["environment"], float(jobs[j]["orientation_yaw"])) for j in kit["jobs"]]

    again = pick(spec, tmp_path / "again", "--per-object", "4")
    assert again.exit_code == 0, again.output
    assert kit_files(tmp_path / "kit") == kit_files(tmp_path / "again")  # same seed: the same bytes
    photo = tmp_path / "kit" / f"{kit['jobs'][0]}.jpg"
    photo.write_bytes(b"a photograph")
    before = kit_files(tmp_path / "kit")
    assert pick(spec, tmp_path / "kit", "--per-object", "4").exit_code == 0  # picked again into the kit
    assert kit_files(tmp_path / "kit") == before and photo.read_bytes() == b"a photograph"
    other = pick(spec, tmp_path / "other", "--per-object", "4", "--seed", "11")
    assert other.exit_code == 0, other.output
    assert json.loads((tmp_path / "other" / "kit.json").read_text())["jobs"] != kit["jobs"]


def test_the_design_replays_with_the_table_policy(tmp_path: Path, monkeypatch) -> None:
    from sweep3d.stages.plan.design import read_design
    from tests.helpers import load_spec

    spec = make_run(tmp_path)
    stub_kit_tools(monkeypatch)
    assert pick(spec, tmp_path / "kit", "--per-object", "2").exit_code == 0
    replay = tmp_path / "replay.toml"
    replay.write_text(spec.read_text().replace('type = "grid"', 'type = "table"\nfile = "kit/design.csv"'))
    loaded = load_spec(replay)  # the table policy binds the file: every cell checked against the spec
    scenes = read_design(tmp_path / "kit" / "design.csv", loaded.controls, [o.name for o in loaded.objects],
                         [e.name for e in loaded.environments], tmp_path)
    assert sum(s.count for s in scenes.values()) == len(json.loads((tmp_path / "kit" / "kit.json").read_text())["jobs"])


def test_near_ties_are_left_out_or_marked(tmp_path: Path, monkeypatch) -> None:
    jobs = job_colours()
    rows = [redblue_row(image_of(j["rgb"]), LABELS[j["object"]]) for j in jobs]
    tied = set(range(0, len(jobs), 2))  # every other job a near tie: p(true) and p(other) 0.02 apart
    for i in tied:
        truth, other = (0.51, 0.49) if rows[i]["correct"] else (0.49, 0.51)
        rows[i] = {**rows[i], "topk_probs": [max(truth, other), min(truth, other)], "label_prob": truth}
    spec = make_run(tmp_path, jobs, rows)
    stub_kit_tools(monkeypatch)
    assert pick(spec, tmp_path / "left", "--per-object", "4").exit_code == 0
    left = json.loads((tmp_path / "left" / "kit.json").read_text())
    assert left["picks"] and not any(p["job"] in tied or p["near_tie"] for p in left["picks"])
    marked = pick(spec, tmp_path / "marked", "--per-object", "36", "--near-ties", "mark")
    assert marked.exit_code == 0, marked.output
    picks = json.loads((tmp_path / "marked" / "kit.json").read_text())["picks"]
    assert {p["job"] for p in picks if p["near_tie"]} == tied  # all jobs picked: the ties flagged
    assert all(abs(p["margin"]) < 0.05 for p in picks if p["near_tie"])


def test_a_folder_of_other_files_or_a_bad_option_is_one_line(tmp_path: Path, monkeypatch) -> None:
    spec = make_run(tmp_path)
    stub_kit_tools(monkeypatch)
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "notes.txt").write_text("mine")
    for args, words in (((str(tmp_path / "busy"),), "holds other files"),
                        ((str(tmp_path / "store" / "kit"),), "inside the store"),
                        ((str(tmp_path / "k"), "--per-object", "0"), "at least 1"),
                        ((str(tmp_path / "k"), "--near-ties", "keep"), "leave or mark")):
        result = pick(spec, Path(args[0]), *args[1:])
        assert result.exit_code == 2, result.output
        assert words in result.output and len(result.output.strip().splitlines()) == 1
    assert (tmp_path / "busy" / "notes.txt").read_text() == "mine" and not (tmp_path / "k").exists()
