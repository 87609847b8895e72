"""The one package tests share besides conftest's fixtures: a spec builder (tiny specs and a cube
mesh written into a folder), the spec loader tests use, synthetic stores and the small pieces
several test files need; beside it, :mod:`.files` (asset files built byte by byte),
:mod:`.doc_blocks` (the docs' code blocks) and :mod:`.realism` (the realism tests' synthetic run).
Tests import from here, never from another test file or from ``benchmarks/``."""

from __future__ import annotations

import hashlib
import io
import json
import math
import re
import textwrap
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from functools import lru_cache
from pathlib import Path
from typing import Any, Iterator

import duckdb
import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
from hypothesis import strategies as st
from PIL import Image

import sweep3d
from sweep3d.assets.sources import blender_version
from sweep3d.cache.blobs import sha256_bytes
from sweep3d.cache.hashing import digest
from sweep3d.cache.store import DIGEST_COLUMN, Store, atomic_write, segment_name, utc_now
from sweep3d.core.pixels import encode_png
from sweep3d.core.truth import encode_mask
from sweep3d.driver import Plan
from sweep3d.report import image_keys
from sweep3d.report.panels import CORE_PANELS
from sweep3d.results import connect
from sweep3d.results.task_views import OUTCOMES
from sweep3d.runner import builtin_catalogue
from sweep3d.runner.pipeline import plan_spec, plans_as_run, write_jobs
from sweep3d.spec.columns import PARAMETERS_METADATA
from sweep3d.spec.framing import Framing
from sweep3d.spec.space import SearchSpace
from sweep3d.stages.infer.prediction_keys import infer_base, key_backend, pred_key
from sweep3d.stages.plan import make_plan
from sweep3d.stages.postprocess.image_keys import image_key
from sweep3d.stages.render.render_keys import parts_key, render_key, scene_key
from sweep3d.stages.render.state import SceneState, in_frame
from sweep3d.stages.render.worker_protocol import EnvironmentRef

# --- definitions ---


def load_spec(source, plugins=None):
    """The :class:`~sweep3d.spec.LoadedSpec` of ``source`` (a path, TOML text or a dict) against
    the built-in plug-ins (or the catalogue ``plugins``): what ``sweep3d.load(source).spec`` is."""
    from sweep3d.runner import builtin_catalogue
    from sweep3d.spec import read_spec

    return read_spec(source, plugins or builtin_catalogue())


#: The spec builder's parts: meshes the tests write (``write_spec`` writes cube.obj), the
#: environments they light them with, and the smallest render.
SPEC_OBJECTS = {"box": ("cube.obj", ["carton"]), "crate": ("cube.obj", ["crate"])}
SPEC_ENVIRONMENTS = {"white": {"color": [1.0, 1.0, 1.0]}, "grey": {"color": [0.5, 0.5, 0.5]},
                "studio": {"hdri": "builtin:studio"}}
TINY_RENDER = {"resolution": 32, "samples": 1, "denoise": False}


def toml_value(value) -> str:
    """``value`` as TOML (what the tests' specs use: text, numbers, booleans, lists)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return repr(value)


def toml_table(header: str, values: dict) -> str:
    return f"{header}\n" + "".join(f"{k} = {toml_value(v)}\n" for k, v in values.items()) + "\n"


def spec_toml(name: str, *, seed: int | None = None, store: str | None = "store", render: dict | None = None,
              model: dict | None = None, objects=("box",), environments=("white",), body: str = "") -> str:
    """A spec's text: ``[experiment]``, ``[render]`` (default :data:`TINY_RENDER`), ``[model]``
    when given, one ``[[objects]]`` per name or (name, mesh, labels), one ``[[environments]]`` per
    name or (name, table), then ``body`` (controls, policy, evaluator, ... as TOML text). Tests
    write the tables they are about and take the rest from here, rather than pasting a whole spec."""
    experiment = {"name": name, **({"seed": seed} if seed is not None else {}), **({"store": store} if store else {})}
    text = toml_table("[experiment]", experiment) + toml_table("[render]", TINY_RENDER if render is None else render)
    if model is not None:
        text += toml_table("[model]", model)
    for obj in objects:
        obj_name, mesh, labels = (obj, *SPEC_OBJECTS[obj]) if isinstance(obj, str) else obj
        text += toml_table("[[objects]]", {"name": obj_name, "mesh": mesh, "labels": labels})
    for env in environments:
        env_name, table = (env, SPEC_ENVIRONMENTS[env]) if isinstance(env, str) else env
        text += toml_table("[[environments]]", {"name": env_name, **table})
    return text + textwrap.dedent(body)


def examples(n: int) -> int:
    """``max_examples`` for a property test that sets its own: ``n``, or a fifth of it in the fast lane."""
    from tests import conftest

    return max(5, round(n * conftest.LANE_SHARE)) if conftest.LANE else n


# from conftest.py
REPO = Path(__file__).resolve().parents[2]  # tests/helpers/__init__.py → the repository


CUBE_OBJ = """\
# unit cube
v -1 -1 -1
v 1 -1 -1
v 1 1 -1
v -1 1 -1
v -1 -1 1
v 1 -1 1
v 1 1 1
v -1 1 1
f 1 2 3 4
f 5 8 7 6
f 1 5 6 2
f 2 6 7 3
f 3 7 8 4
f 5 1 4 8
"""


def write_cube(folder: Path, name: str = "cube.obj") -> Path:
    path = folder / name
    path.write_text(CUBE_OBJ)
    return path


def write_spec(folder: Path, body: str, *, cube: bool = True, name: str = "spec.toml") -> Path:
    """Write a spec into ``folder`` (with a cube mesh beside it unless ``cube`` is False)."""
    if cube:
        write_cube(folder)
    path = folder / name
    path.write_text(textwrap.dedent(body))
    return path


TINY_SPEC = spec_toml("tiny", seed=7, model={"batch_size": 8}, environments=("white", "studio"), body="""\
[[controls]]
type = "orientation"
yaw = [0, 45]

[[controls]]
type = "blur"
sigma = [0.0, 1.5]

[policy]
type = "grid"
""")


#: Two models in place of TINY_SPEC's ``[model]``: the same network by two backends.
TWO_MODELS = """\
[[models]]
name = "efficientnet-lite0"
batch_size = 8

[[models]]
name = "efficientnet-lite0"
id = "lite0-onnx"
backend = "onnx"
batch_size = 8
"""


#: Post-processed images written to the store (the default makes them in memory): the tests of
#: damaged, missing and verified blobs have image blobs to damage (tests/cache/test_image_store.py
#: checks that both ways give the same results).
STORE_ALL = """
[postprocess]
store = "all"
"""


def plan_for(loaded, model_digest: str | None = None):
    """Plan ``loaded`` as a run would; a ``model_digest`` stands in for the model's (none is loaded)."""
    from sweep3d.spec.framing import Framing

    if model_digest is None:
        return plan_spec(loaded)
    resolution = loaded.render.resolution
    assert resolution != "model", "a stand-in digest needs a pixel resolution"
    return make_plan(loaded, framing=Framing.full(resolution), model_digest=model_digest, blender=blender_version())




# from test_aggregate_views.py
T0 = datetime(2024, 1, 1)


def make_store(folder: Path, rows: list[dict[str, Any]], experiment: str = "e") -> duckdb.DuckDBPyConnection:
    """A store whose jobs are ``rows`` (scene, control columns, ``correct``; ``valid`` default True)."""
    store = Store(folder / "store")
    jobs, predictions = [], []
    for i, row in enumerate(rows):
        row = dict(row)
        correct, valid = row.pop("correct"), row.pop("valid", True)
        key = f"k{i}"
        jobs.append({"experiment": experiment, "job": i, "object": row.pop("object", "obj"),
                     "environment": row.pop("environment", "env"), **row,
                     "render_key": key, "image_key": key, "pred_key": key})
        predictions.append({"pred_key": key, "image_key": key, "created_at": T0, "valid": valid,
                            "correct": correct if valid else None, "top1_label": row.get("prediction", "thing"),
                            "topk": [0], "topk_labels": [row.get("prediction", "thing")], "topk_probs": [0.9],
                            "loss": 1.0})
    store.write_table_file(store.jobs_path(experiment), pa.Table.from_pylist(jobs))
    store.append("predictions", predictions)
    return connect(store, experiment)


def rows_of(con: duckdb.DuckDBPyConnection, sql: str) -> list[dict[str, Any]]:
    cursor = con.execute(sql)
    names = [d[0] for d in cursor.description]
    return [dict(zip(names, r)) for r in cursor.fetchall()]




# from test_paired.py
def paired_spec(seed: int, policy: str) -> str:
    """Two objects × two environments; the camera applies to "grey" only, so its scenes have an
    extra control. The environments are lit without a key light (as plain backgrounds were before
    they had one): the keys of the frozen plans."""
    unlit = {"key_light": False}
    return spec_toml("freeze", seed=seed, objects=("box", "crate"),
                     environments=(("white", SPEC_ENVIRONMENTS["white"] | unlit), ("grey", SPEC_ENVIRONMENTS["grey"] | unlit)),
                     body=f"""\
[[controls]]
type = "orientation"
yaw = {{ range = [-180, 180] }}
pitch = [0, 15, 30]

[[controls]]
type = "camera"
zoom = {{ range = [0.8, 2.0], log = true }}
environments = ["grey"]

[[controls]]
type = "blur"
sigma = [0, 1, 2]

[policy]
{policy}
""")


def every_job(p) -> list:
    return list(p.jobs) + list(p.out_of_frame)


def scene_values(p, control: str) -> dict[tuple[str, str], list[dict[str, Any]]]:
    """(object, environment) → the values of ``control`` of its jobs, in job order."""
    out: dict[tuple[str, str], list] = {}
    for job in sorted(every_job(p), key=lambda j: j.index):
        out.setdefault((job.object, job.environment), []).append(job.values[control])
    return out




# from test_reliability.py


def render_row(key: str, minutes: int = 0, digest: str | None = None, seconds: float = 1.0) -> dict:
    return {"render_key": key, "width": 4, "height": 4, "valid": True, "seconds": seconds,
            "created_at": T0 + timedelta(minutes=minutes), DIGEST_COLUMN: digest}


def add_render(store: Store, key: str, minutes: int = 0) -> bytes:
    """A blob and its row, as the render stage writes them."""
    import numpy as np

    data = encode_png(np.full((4, 4, 3), (minutes % 10) / 10, np.float32))
    atomic_write(store.blob_path(key), data)
    store.append("renders", [render_row(key, minutes, sha256_bytes(data))])
    return data


class HashCounter:
    """Counts the blobs :func:`damaged_blobs` hashes (stands in for ``sha256_bytes``)."""

    def __init__(self, monkeypatch) -> None:
        import sweep3d.cache.blobs as blobs

        self.calls = 0
        self.real = blobs.sha256_bytes
        monkeypatch.setattr(blobs, "sha256_bytes", self)

    def __call__(self, data: bytes) -> str:
        self.calls += 1
        return self.real(data)




# from test_store.py
def store_tree(root: Path) -> dict[str, tuple[int, int]]:
    """Every file under ``root`` with its size and mtime: what a query must leave as it was."""
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*") if p.is_file()}


class FixedUuid:
    """A uuid whose ``hex`` is ``fixed``: patched in for ``uuid.uuid4``, a test can put something
    (a link to /dev/full: a real full disk) where a temp file will be written."""

    hex = "fixed"


def one_line(output: str) -> str:
    lines = [line for line in output.splitlines() if line.strip()]
    assert len(lines) == 1, output
    return lines[0]




# from test_lights.py
CONTROLS = builtin_catalogue().controls


def sphere_obj(path: Path, n: int = 16) -> str:
    """A UV sphere: smooth shading shows which side a light is on."""
    rings = [(math.sin(math.pi * i / n), math.cos(math.pi * i / n)) for i in range(n + 1)]
    verts = [(s * math.cos(math.pi * j / n), s * math.sin(math.pi * j / n), c) for s, c in rings for j in range(2 * n)]
    faces = [(i * 2 * n + j, i * 2 * n + (j + 1) % (2 * n), (i + 1) * 2 * n + (j + 1) % (2 * n), (i + 1) * 2 * n + j)
             for i in range(n) for j in range(2 * n)]
    path.write_text("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in verts)
                    + "".join("f " + " ".join(str(k + 1) for k in face) + "\n" for face in faces))
    return str(path)


def render(scene, mesh: str, env: EnvironmentRef, controls: list[tuple[str, dict]], **camera) -> np.ndarray:
    state = SceneState(**camera)
    for name, values in controls:
        control = CONTROLS.get(name)(name, name)
        control.apply(state, control.params(values))
    scene.prepare(mesh, env)
    scene.pose_scene(state)
    return scene.render()




# from test_plugin_code.py
SCENE_CONTROL = '''
from pydantic import Field
from sweep3d.core.control import ControlParams
from sweep3d.stages.render import RenderedControl

RED = (1.0, 0.0, 0.0, 1.0)


class Slab(RenderedControl):
    class Params(ControlParams):
        size: float = Field(0.0, ge=0.0)

    def edit(self, scene, params):
        bpy = scene.bpy
        s = params.size
        mesh = bpy.data.meshes.new("slab")
        mesh.from_pydata([(-s, -1.5, -s), (s, -1.5, -s), (s, -1.5, s), (-s, -1.5, s)], [], [(0, 1, 2, 3)])
        material = bpy.data.materials.new("slab")
        material.use_nodes = True
        material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = RED
        mesh.materials.append(material)
        scene.add(bpy.data.objects.new("slab", mesh))
'''




# from test_report.py
ARTIFACTS = REPO / "test-artifacts"


def watch_page(page: Any) -> dict[str, list]:
    """What ``page`` does from now on, for :func:`assert_clean`: its script errors, console
    errors, requests, and dialogs (dismissed)."""
    events: dict[str, list] = {"errors": [], "console": [], "requests": [], "dialogs": []}
    page.on("pageerror", lambda exc: events["errors"].append(str(exc)))
    page.on("console", lambda msg: events["console"].append(msg.text) if msg.type == "error" else None)
    page.on("request", lambda req: events["requests"].append(req.url))
    page.on("dialog", lambda dialog: (events["dialogs"].append(dialog.message), dialog.dismiss()))
    return events


@contextmanager
def open_page(chromium: Any, path: Path, wait_all: bool = True, width: int = 1280,
              unfold: bool = True) -> Iterator[tuple[Any, dict[str, list]]]:
    """A page of the session's headless Chromium (the ``chromium`` fixture), in a fresh browser
    context ``width`` pixels wide, showing ``path`` once it is interactive (and, with ``wait_all``,
    once every figure is drawn and every image loaded); events collected for :func:`assert_clean`.
    With ``unfold`` every folded panel is opened, as a reader clicking each title would (the
    first screen alone: ``unfold=False``)."""
    context = chromium.new_context(viewport={"width": width, "height": 900})
    try:
        page = context.new_page()
        events = watch_page(page)
        page.goto(path.as_uri())
        page.wait_for_function("() => document.documentElement.dataset.ready === '1'", timeout=60_000)
        if wait_all:
            page.wait_for_function("() => document.documentElement.dataset.drawn === '1'", timeout=60_000)
            page.wait_for_function("() => Array.from(document.images).every(i => i.complete)", timeout=10_000)
        if unfold:
            page.evaluate("() => window.sweep3d.unfoldAll()")
        yield page, events
    finally:
        context.close()


def assert_clean(path: Path, events: dict[str, list]) -> None:
    """No script error, no console error, no dialog, and no request but the file itself (and the
    in-page ``blob:`` URLs a PNG export makes)."""
    assert events["errors"] == []
    assert events["console"] == []
    assert events["dialogs"] == []
    assert {url for url in events["requests"] if not url.startswith("blob:")} == {path.as_uri()}


def cell_centre(page: Any, x: int, y: int) -> tuple[float, float]:
    """Page coordinates of the centre of the explorer heat map's cell (x, y), scrolled into view
    first (a click outside the viewport reaches nothing)."""
    page.locator("#explorer-plot").scroll_into_view_if_needed()
    return tuple(page.evaluate(
        """([x, y]) => {
             const gd = document.getElementById('explorer-plot'), box = gd.getBoundingClientRect();
             const xa = gd._fullLayout.xaxis, ya = gd._fullLayout.yaxis;
             return [box.left + xa._offset + xa.l2p(x), box.top + ya._offset + ya.l2p(y)];
           }""", [x, y]))




# from report_scale.py
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


SCALE_SPEC = """\
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
    import sweep3d

    spec = write_scale_spec(folder, results)
    loaded = sweep3d.load(spec).spec
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


def write_scale_spec(folder: Path, results: int) -> Path:
    """The benchmark's spec (5 objects × 4 environments, random yaw, 3 elevations, 3 blurs)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "cube.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scenes = len(OBJECTS) * len(ENVIRONMENTS)
    objects = "\n".join(f'[[objects]]\nname = "{n}"\nmesh = "cube.obj"\nlabels = ["{label}"]\n'
                        for n, (label, _, _) in OBJECTS.items())
    environments = "\n".join(f'[[environments]]\nname = "{n}"\ncolor = [{", ".join(map(str, c))}]\n'
                             for n, c in ENVIRONMENTS.items())
    spec = folder / "spec.toml"
    spec.write_text(SCALE_SPEC.format(objects=objects, environments=environments, samples=math.ceil(results / scenes)))
    return spec


def synthetic_tables(experiment: str, results: int, seed: int) -> tuple[pa.Table, pa.Table]:
    """The jobs table and the predictions table of ``results`` synthetic results, built column-wise."""
    from sweep3d.stages.infer.evaluators import ClassificationEvaluator
    from sweep3d.stages.infer.infer_stage import predictions_schema

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




# from test_parts.py
def direction(azimuth: float, elevation: float) -> np.ndarray:
    """A unit vector at ``azimuth`` degrees from the front (-Y) towards the right (+X)."""
    az, el = math.radians(azimuth), math.radians(elevation)
    return np.array([[math.cos(el) * math.sin(az), -math.cos(el) * math.cos(az), math.sin(el)]])




# from test_report.py
PANEL_IDS = [p.id for p in CORE_PANELS]  # every report has these; optional ones are tested where shown


def page_thumbnails(html: str) -> list[str | None]:
    found = re.search(r'<script type="application/json" id="thumbs">(.*?)</script>', html, re.S)
    assert found, "the page has no thumbnail block"
    return json.loads(found.group(1))


def screenshot_panels(page: Any, prefix: str) -> None:
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / f"{prefix}.png"), full_page=True)
    for panel in PANEL_IDS:
        page.locator(f"#{panel}").screenshot(path=str(ARTIFACTS / f"{prefix}-{panel}.png"))




# from test_plan_columns.py
def reference_jobs(spec, *, framing: Framing, model_digest: str, blender: str) -> list[tuple]:
    """The jobs of ``spec`` as the planner made them job by job: (index, object, environment,
    values, render, image, pred, point, parts, in frame)."""
    from sweep3d.assets.sources import mesh_digest

    rendered = sorted((c for c in spec.controls if c.control.stage == "render"),
                      key=lambda c: (c.control.order, spec.controls.index(c)))
    post = [c for c in spec.controls if c.control.stage == "post"]
    settings_part = spec.render.key_part(framing.key_part())
    base = infer_base(model_digest, {"kind": spec.evaluator.kind, "top_k": spec.evaluator.params.get("top_k", 5)},
                      key_backend(spec, spec.model))
    out = []
    for obj in spec.objects:
        object_digest = mesh_digest(spec.meshes[obj.name], spec.store)
        truth = list(spec.labels[obj.name])
        for env in spec.environments:
            scene = scene_key(blender, settings_part, object_digest, env.key_part(None))
            scene_controls = [c for c in spec.controls if c.applies_to(obj.name, env.name)]
            space = SearchSpace(scene_controls)
            seed = int(digest([spec.experiment.seed, obj.name, env.name])[:15], 16)
            for point in spec.policy.points(space.shape, seed, {}):
                values = space.values(point)
                models = {c.id: c.control.params(values[c.id]) for c in scene_controls}
                params = {key: model.model_dump() for key, model in models.items()}
                render = render_key(scene, _parts(rendered, params))
                effective = [c for c in post if c.id in params and not c.control.is_identity(params[c.id])]
                seeded = any(getattr(c.control, "stochastic", False) for c in effective)
                image = image_key(render, _parts(post, params), spec.experiment.seed if seeded else None)
                state = SceneState()
                for inst in rendered:
                    if inst.id in models:
                        inst.control.apply(state, models[inst.id])
                out.append((len(out), obj.name, env.name, params, render, image, pred_key(base, image, truth),
                            point, parts_key(render) if spec.report.part_visibility else None, in_frame(state)))
    return out


def _parts(controls, params: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    return [c.control.key_part(params[c.id]) for c in controls
            if c.id in params and not c.control.is_identity(params[c.id])]


finite = st.floats(allow_nan=False, allow_infinity=False)


values = st.recursive(st.none() | st.booleans() | st.integers() | finite | st.text(max_size=5),
                      lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3),
                      max_leaves=8)




# from test_tasks_report.py
W, H = 64, 48  # stored images


MIN_VISIBLE = 0.2


PARAMETERS = ["orientation_yaw", "blur_sigma"]


TASKS_SPEC = spec_toml("tasks",
        render={},
        objects=(("mug", "cube.obj", ["coffee mug"]), ("ball", "cube.obj", ["soccer ball"])),
        body="""\
[model]
name = "efficientnet-lite0"

[evaluator]
passes = ["mask"]
min_visible = 0.2

[[controls]]
type = "orientation"
yaw = [0, 90, 180]

[[controls]]
type = "blur"
sigma = [0.0, 1.0]

[policy]
type = "grid"
""")


@dataclass
class Job:
    """One synthetic job and what is true of it."""

    job: int
    object: str
    yaw: float
    sigma: float
    in_frame: bool = True
    visible: int = 600  # visible pixels of the object
    fraction: float | None = 0.8
    framed: int = 750  # pixels of its unoccluded silhouette in the image
    truth: bool = True  # a truth row exists (else evaluable is unknown: counted)
    valid: bool = True
    outcome: str = "correct"
    iou: float | None = 0.8
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def evaluable(self) -> bool | None:
        if not self.in_frame:
            return False
        if not self.truth:
            return None
        return self.fraction is not None and self.fraction >= MIN_VISIBLE

    @property
    def counted(self) -> bool:
        return self.valid and self.evaluable is not False

    @property
    def reason(self) -> str:
        if not self.in_frame or self.fraction is None or self.framed == 0:
            return "out of frame"
        return "fully occluded" if self.visible == 0 else "hidden"


def synthetic_jobs() -> list[Job]:
    """72 jobs over 2 objects × 3 yaws × 2 blurs: some out of frame, hidden, without a truth row,
    invalid; outcomes and IoUs that depend on the yaw and the object."""
    rng = np.random.default_rng(5)
    jobs = []
    for i in range(72):
        job = Job(i, ["mug", "ball"][i % 2], [0.0, 90.0, 180.0][(i // 2) % 3], [0.0, 1.0][(i // 6) % 2])
        weights = {0.0: [0.7, 0.1, 0.1, 0.1], 90.0: [0.3, 0.2, 0.3, 0.2], 180.0: [0.5, 0.3, 0.1, 0.1]}[job.yaw]
        job.outcome = str(rng.choice(OUTCOMES, p=weights))
        job.iou = {"correct": rng.uniform(0.55, 0.95), "wrong_class": rng.uniform(0.5, 0.9),
                   "wrong_box": rng.uniform(0.05, 0.45), "missed": None}[job.outcome]
        if job.object == "ball" and job.iou is not None:
            job.iou *= 0.9
        if i % 16 == 15:
            job.in_frame, job.visible, job.fraction = False, 0, None
        elif i % 10 == 3:  # hidden: some of it shows, less than min_visible; wrong on purpose
            job.visible, job.fraction, job.outcome, job.iou = 40, 0.05, "wrong_class", 0.7
        elif i == 4:  # in frame by the plan's geometry, but no pixel would reach the image even unoccluded
            job.visible, job.fraction, job.framed, job.outcome, job.iou = 0, 0.0, 0, "missed", None
        elif i == 10:  # in the image, but wholly behind an occluder
            job.visible, job.fraction, job.outcome, job.iou = 0, 0.0, "missed", None
        elif i == 8:
            job.truth = False
        elif i % 13 == 5:
            job.valid, job.outcome, job.iou = False, None, None
        jobs.append(job)
    return jobs


TRUE_BOX = (10, 8, 40, 30)


def pred_box(job: Job) -> tuple[float, float, float, float] | None:
    """Shifted right for a wrong box; none when missed."""
    if job.outcome in (None, "missed"):
        return None
    shift = 18.0 if job.outcome == "wrong_box" else 2.0
    x0, y0, x1, y1 = TRUE_BOX
    return (x0 + shift, y0 + 1.0, x1 + shift, y1 + 1.0)


def prediction(key: str, image: str, job: Job, kind: str, model: str) -> dict[str, Any]:
    label = "coffee mug" if job.object == "mug" else "soccer ball"
    if job.outcome == "wrong_class":
        label = "hidden thing" if job.fraction is not None and job.fraction < MIN_VISIBLE else "teapot"
    row = {"pred_key": key, "image_key": image, "model": model, "created_at": T0, "valid": job.valid,
           "correct": job.outcome == "correct" if job.valid else None, "top1_label": label if job.valid else None}
    if kind in ("classification", "localization"):  # detection and segmentation rank no classes
        row.update(topk=[0], topk_labels=[label], topk_probs=[0.9], loss=1.0 + job.job / 100)
    if kind in ("localization", "detection", "segmentation"):
        row.update(outcome=job.outcome, class_correct=job.outcome in ("correct", "wrong_box") if job.valid else None,
                   iou=job.iou)
    if kind in ("localization", "detection"):
        box = pred_box(job) or (None,) * 4
        row.update(dict(zip(("pred_x0", "pred_y0", "pred_x1", "pred_y1"), box)))
    if kind == "segmentation":
        mask = np.zeros((H, W), bool)
        if pred_box(job):
            x0, y0, x1, y1 = (int(v) for v in pred_box(job))
            mask[y0:y1, x0:x1] = True
        row.update(pred_pixels=int(mask.sum()), true_pixels=job.visible, pred_mask=encode_mask(mask))
    return row




# from test_own_jobs.py
BLUR = "sigma = [0.0, 1.5]"


#: The same experiment ("tiny", 8 jobs) with blur 0 and 3, and with blur 0 and 2: half their jobs are shared.
SPEC_03, SPEC_02 = TINY_SPEC.replace(BLUR, "sigma = [0.0, 3.0]"), TINY_SPEC.replace(BLUR, "sigma = [0.0, 2.0]")


def fake_run(spec: sweep3d.Experiment, run_id: str = "run") -> None:
    """What a run of ``spec`` leaves in its store: its jobs file, a prediction and an image for
    each job (a job is correct when its blur is 0), and its row in ``runs`` (the latest)."""
    store = Store(spec.store)
    started = datetime(2024, 1, 1 + len(store.segments("runs")))
    store.append("runs", [{"run_id": run_id, "experiment": spec.name, "spec_path": str(spec.spec.path),
                           "spec": spec.spec.text(), "jobs": 8, "started_at": started, "created_at": started,
                           "seconds": 1.0}])
    plans = plans_as_run(spec.spec, store)
    predict(plans[0], store)
    write_jobs(plans, store)


def predict(plan: Plan, store: Store) -> None:
    """A prediction and an image for each job of ``plan`` the store lacks: correct when its blur is 0."""
    have = store.keys("predictions") if store.segments("predictions") else set()
    rows = []
    for job in plan.jobs:
        if job.pred_key in have:
            continue
        blur = next(v["sigma"] for i, v in job.values.items() if i.startswith("blur"))
        rows.append({"pred_key": job.pred_key, "image_key": job.image_key, "created_at": datetime(2024, 1, 1),
                     "valid": True, "correct": blur == 0, "top1_label": "carton", "loss": 1.0 + blur})
        path = store.blob_path(job.image_key)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(_png())
    store.append("predictions", rows)


def _png() -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(buffer, format="PNG")
    return buffer.getvalue()


#: The headless Chromium the browser tests drive (``apt-get install chromium``), and its flags.
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-sync"]


def scene_render_keys(path: Path) -> dict[tuple[str, int], str]:
    """The render key of each (environment, yaw) of the spec at ``path`` (a TINY_SPEC-like grid)."""
    plan = plan_for(load_spec(path), "stand-in")
    return {(j.environment, j.values["orientation"]["yaw"]): j.render_key for j in plan.jobs}
