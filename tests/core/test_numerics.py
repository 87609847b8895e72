"""Numerical stability: extreme but legal values render and finish, NaN/inf is flagged invalid
and never averaged, softmax and loss are stable, aggregates are exact at 10⁶ rows, and sampling
and aggregation keep their invariants (hypothesis)."""

from __future__ import annotations

import math
import struct
import sys
from fractions import Fraction
from pathlib import Path

import duckdb
import numpy as np
import pyarrow as pa
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sweep3d.cache.store import Store
from sweep3d.results import connect, summarise
from sweep3d.runner.pipeline import run
from sweep3d.spec.params import Range
from sweep3d.stages.infer import ClassificationEvaluator, LabelMap
from sweep3d.stages.infer.evaluators import Truth, log_softmax
from tests.helpers import CUBE_OBJ, examples, load_spec, spec_toml, write_spec


def write_exr(path: Path, rgb: np.ndarray) -> None:
    """A minimal uncompressed scanline OpenEXR (float32 R, G, B): it keeps NaN and inf as they are.

    Args:
        rgb: float32 (H, W, 3).
    """
    h, w, _ = rgb.shape

    def attr(name: str, kind: str, value: bytes) -> bytes:
        return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value

    channels = b"".join(c.encode() + b"\0" + struct.pack("<iB3xii", 2, 0, 1, 1) for c in "BGR") + b"\0"
    window = struct.pack("<iiii", 0, 0, w - 1, h - 1)
    header = (b"\x76\x2f\x31\x01" + struct.pack("<i", 2)
              + attr("channels", "chlist", channels) + attr("compression", "compression", b"\0")
              + attr("dataWindow", "box2i", window) + attr("displayWindow", "box2i", window)
              + attr("lineOrder", "lineOrder", b"\0") + attr("pixelAspectRatio", "float", struct.pack("<f", 1.0))
              + attr("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0))
              + attr("screenWindowWidth", "float", struct.pack("<f", 1.0)) + b"\0")
    rows = []
    for y in range(h):
        data = b"".join(np.ascontiguousarray(rgb[y, :, c], dtype="<f4").tobytes() for c in (2, 1, 0))
        rows.append(struct.pack("<ii", y, len(data)) + data)
    offset = len(header) + 8 * h
    table = b""
    for row in rows:
        table += struct.pack("<Q", offset)
        offset += len(row)
    path.write_bytes(header + table + b"".join(rows))


def poisoned_hdri(path: Path) -> Path:
    """A 32×16 sky with patches of NaN, +inf and -inf and a 3e38 hot spot."""
    rgb = np.full((16, 32, 3), 0.8, np.float32)
    rgb[2:6, 2:10] = np.nan
    rgb[8:12, 12:20] = np.inf
    rgb[0:2, 20:30] = -np.inf
    rgb[12:16, 28:32] = 3e38
    write_exr(path, rgb)
    return path


def blazing_hdri(path: Path) -> Path:
    """A 32×16 sky as bright as a legal map may be: a 1e6 hot spot (the load's bound) on 0.8."""
    rgb = np.full((16, 32, 3), 0.8, np.float32)
    rgb[12:16, 28:32] = 1e6
    write_exr(path, rgb)
    return path


def cube(scale: float) -> str:
    return "".join(f"v {' '.join(str(float(c) * scale) for c in line.split()[1:])}\n" if line.startswith("v ")
                   else line + "\n" for line in CUBE_OBJ.splitlines())


# -- extreme but legal values through the whole pipeline --------------------------------------

EXTREME_SPEC = spec_toml("extremes",
        seed=1,
        objects=(("speck", "speck.obj", ["carton"]), ("giant", "giant.obj", ["carton"])),
        environments=(("poisoned", {"hdri": "poisoned.exr", "strength": 1000000.0}), "white"),
        body="""\
[[controls]]
type = "camera"
zoom = [0.001, 1000.0]
elevation = [-90.0, 90.0]
environments = ["white"]  # the HDRI world renders slowly at strength 10¹²: two jobs there are enough

[[controls]]
type = "orientation"
pitch = 90.0

[[controls]]
type = "hdri"
strength = 1000000.0

[policy]
type = "grid"
""")


@pytest.mark.slow
def test_extreme_legal_values_finish_and_no_nan_reaches_the_results(tmp_path: Path) -> None:
    """Objects 1e-6 and 1e6 units across, zoom 1e-3 and 1e3, elevation ±90° with pitch 90°
    (gimbal lock), an HDRI with a 1e6 hot spot at strength 10¹² overall: every job ends with
    either a finite, valid prediction or valid = false, and accuracy counts only valid ones. A map
    with NaN/±inf pixels is refused at load (tests/assets/test_input_audit.py), so it is not rendered."""
    (tmp_path / "speck.obj").write_text(cube(5e-7))
    (tmp_path / "giant.obj").write_text(cube(5e5))
    blazing_hdri(tmp_path / "poisoned.exr")
    spec = write_spec(tmp_path, EXTREME_SPEC, cube=False)

    result = run(load_spec(spec))
    assert result.failed == 0, [e for o in result.outcomes for e in o.errors]
    assert len(result.plan.jobs) == 10 and result.outcome("infer").computed == 10

    con = connect(Store(tmp_path / "store"), "extremes")
    rows = con.execute(
        "SELECT r.valid, p.valid, p.correct, p.loss, p.label_prob, p.topk_probs FROM results p "
        "JOIN renders r USING (render_key)").fetchall()
    assert len(rows) == 10
    for render_valid, valid, correct, loss, prob, topk in rows:
        if not render_valid:
            assert valid is False and correct is None and loss is None
        if valid:
            assert correct is not None and math.isfinite(loss) and loss >= 0 and 0 <= prob <= 1
            assert all(math.isfinite(p) for p in topk)
    summary = summarise(con, result.plan.columns)
    assert summary.evaluated == 10
    valid_rows = [r for r in rows if r[1]]
    assert summary.invalid == 10 - len(valid_rows)
    assert summary.accuracy == (sum(bool(r[2]) for r in valid_rows) / len(valid_rows) if valid_rows else None)
    # 8-bit renders are finite (and valid) however bright the sky: no NaN flows. A float readback
    # that did see NaN would flag the render, as tested below.
    assert all(r[0] for r in rows)


FLOAT_RENDER = """
import sys
from pathlib import Path

import numpy as np

from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderSettings
from sweep3d.stages.render.cycles.scene import BlenderScene
from sweep3d.stages.render.state import SceneState

folder, hdri, mesh = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
scene = BlenderScene(RenderSettings(resolution=32, samples=1, denoise=False), folder)
scene.prepare(mesh, EnvironmentRef(hdri=hdri, strength=1e6))
scene.pose_scene(SceneState())
out = scene.scene.render.image_settings
out.file_format, out.color_depth, out.color_mode = "OPEN_EXR", "32", "RGBA"
scene.scene.render.filepath = str(folder / "frame.exr")
scene.bpy.ops.render.render(write_still=True)
image = scene.bpy.data.images.load(str(folder / "frame.exr"))
pixels = np.array(image.pixels[:], dtype=np.float32)
print("pixels", pixels.size // 4, "finite", bool(np.isfinite(pixels).all()), "max", float(np.nanmax(pixels)))
"""


@pytest.mark.blender
def test_cycles_turns_nan_and_inf_sky_pixels_into_finite_light(tmp_path: Path) -> None:
    """Rendered to a float EXR (not the 8-bit PNG the worker reads back), a world with NaN,
    +inf and -inf pixels at strength 10⁶ is still finite: Blender keeps them out of the image.
    (In a child process: importing bpy here would change sys.path for later render workers.)"""
    import subprocess

    from tests.helpers import REPO, write_cube

    hdri = poisoned_hdri(tmp_path / "poisoned.exr")
    done = subprocess.run([sys.executable, "-c", FLOAT_RENDER, str(tmp_path), str(hdri), str(write_cube(tmp_path))],
                          capture_output=True, text=True, timeout=300, env={**__import__("os").environ,
                                                                            "PYTHONPATH": str(REPO)})
    line = next((x for x in done.stdout.splitlines() if x.startswith("pixels")), done.stdout + done.stderr)
    assert line.startswith("pixels 1024 finite True"), line


# -- NaN is flagged, propagated and excluded --------------------------------------------------

POISON_MODULE = "sweep3d_test_poison"
POISON = '''
import numpy as np
from pydantic import Field

from sweep3d.core.control import ControlParams
from sweep3d.stages.postprocess import PostControl


class Poison(PostControl):
    """Puts NaN into a corner of the image (amount 1) or leaves it alone (amount 0)."""

    class Params(ControlParams):
        amount: int = Field(0, ge=0, le=1)

    def apply(self, image, params, rng):
        out = image.copy()
        out[:4, :4] = np.nan
        return out
'''


@pytest.mark.slow
def test_invalid_renders_and_images_make_invalid_predictions_excluded_from_accuracy(tiny_copy: Path,
                                                                                   monkeypatch) -> None:
    """valid = false flows from renders to images to predictions, and accuracy leaves those out.

    A render row is marked non-finite (as a float readback of a NaN render would write it), and
    a post control puts real NaN pixels into half of the images."""
    (tiny_copy / f"{POISON_MODULE}.py").write_text(POISON)
    monkeypatch.syspath_prepend(str(tiny_copy))
    monkeypatch.delitem(sys.modules, POISON_MODULE, raising=False)
    spec = tiny_copy / "spec.toml"
    spec.write_text(spec.read_text().replace("[policy]", f'[[controls]]\ntype = "{POISON_MODULE}:Poison"\n'
                                                         'amount = [0, 1]\n\n[policy]'))
    store = Store(tiny_copy / "store")
    jobs = connect(store, "tiny").execute("SELECT render_key, image_key, pred_key FROM jobs ORDER BY job").fetchall()
    bad_render = jobs[0][0]
    renders = store.table("renders").to_pylist()
    marked = [dict(r, valid=False) for r in renders if r["render_key"] == bad_render]
    with store.lock():  # as if the render had come back with NaN pixels in the first place
        store.drop_rows("renders", {bad_render})
        store.append("renders", marked, store.table("renders").schema)
        store.drop_rows("images", {i for r, i, _ in jobs if r == bad_render and i != r})
        store.drop_rows("predictions", {p for r, _, p in jobs if r == bad_render})

    result = run(load_spec(spec))
    assert result.failed == 0
    assert result.outcome("render").computed == 0  # the marked render is reused, not redone

    con = connect(Store(tiny_copy / "store"), "tiny")
    rows = con.execute(
        "SELECT j.render_key, j.Poison_amount, i.valid, p.valid, p.correct, p.loss, p.top1 FROM jobs j "
        "JOIN predictions p USING (pred_key) LEFT JOIN images i ON i.image_key = j.image_key").fetchall()
    assert len(rows) == 16
    for render_key, amount, image_valid, valid, correct, loss, top1 in rows:
        expected = render_key != bad_render and amount == 0
        assert valid is expected, (render_key == bad_render, amount, image_valid, valid)
        if image_valid is not None:
            assert image_valid is expected
        if not valid:
            assert correct is None and loss is None and top1 is None  # never shown to the model
        else:
            assert math.isfinite(loss)
    summary = summarise(con, result.plan.columns)
    invalid = sum(1 for r in rows if not r[3])
    assert invalid == 10  # 8 poisoned images + the 2 unpoisoned jobs of the marked render
    assert summary.invalid == invalid
    valid = [r for r in rows if r[3]]
    assert summary.accuracy == sum(bool(r[4]) for r in valid) / len(valid)


# -- softmax and loss ------------------------------------------------------------------------

F32_MAX = float(np.finfo(np.float32).max)


def _names(n: int) -> LabelMap:
    return LabelMap([[f"c{i}"] for i in range(n)])


@pytest.mark.parametrize("logits, label, correct", [
    ([F32_MAX, -F32_MAX, 0.0], 0, True),  # the whole float32 range in one row
    ([-F32_MAX, F32_MAX, 0.0], 0, False),
    ([F32_MAX, F32_MAX, F32_MAX], 2, False),  # ties go to the first class
    ([1e-45, 0.0, -1e-45], 0, True),  # subnormals
    ([3e38] + [-3e38] * 999, 0, True),  # 1000 classes
    ([-3e38] * 999 + [3e38], 0, False),
])
def test_softmax_and_loss_are_finite_for_extreme_float32_logits(logits, label, correct) -> None:
    x = np.array([logits], dtype=np.float32)
    logp = log_softmax(x)
    assert np.isfinite(logp).all() and np.exp(logp).sum() == pytest.approx(1.0, abs=1e-12)
    row = ClassificationEvaluator(top_k=3).evaluate(x, [Truth((label,))], _names(x.shape[1]))[0]
    assert row["valid"] and row["correct"] is correct
    assert math.isfinite(row["loss"]) and row["loss"] >= 0
    assert 0.0 <= row["label_prob"] <= 1.0 and all(0.0 <= p <= 1.0 for p in row["topk_probs"])
    assert row["loss"] == pytest.approx(-math.log(row["label_prob"]), rel=1e-9) if row["label_prob"] > 0 else True


def test_a_label_set_adds_its_probabilities_without_overflow() -> None:
    x = np.array([[3e38, 3e38, -3e38, 0.0]], dtype=np.float32)
    row = ClassificationEvaluator(top_k=2).evaluate(x, [Truth((0, 1))], _names(4))[0]
    assert row["label_prob"] == pytest.approx(1.0) and row["loss"] == pytest.approx(0.0, abs=1e-12)
    row = ClassificationEvaluator(top_k=2).evaluate(x, [Truth((1,))], _names(4))[0]
    assert row["label_prob"] == pytest.approx(0.5) and row["loss"] == pytest.approx(math.log(2))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_any_non_finite_logit_makes_the_row_invalid_not_nan(bad) -> None:
    x = np.array([[1.0, bad, 0.0], [0.0, 1.0, 2.0]], dtype=np.float32)
    rows = ClassificationEvaluator(top_k=2).evaluate(x, [Truth((0,)), Truth((2,))], _names(3))
    assert rows[0]["valid"] is False and rows[0]["loss"] is None and rows[0]["correct"] is None
    assert rows[1]["valid"] and rows[1]["correct"] and math.isfinite(rows[1]["loss"])


# -- aggregates at scale ---------------------------------------------------------------------


def _results_connection(table: pa.Table) -> duckdb.DuckDBPyConnection:
    con = duckdb.connect()
    con.register("results_data", table)
    con.execute("CREATE VIEW results AS SELECT * FROM results_data")
    con.execute("CREATE VIEW jobs AS SELECT * EXCLUDE (valid, correct) FROM results_data")  # parameters live in jobs
    return con


def _synthetic(n: int, seed: int) -> pa.Table:
    rng = np.random.default_rng(seed)
    valid = rng.random(n) > 0.03
    correct = rng.random(n) < 0.37
    return pa.table({
        "job": np.arange(n), "object": rng.choice(["mug", "toaster", "ball"], n),
        "environment": rng.choice(["studio", "night"], n), "zoom": rng.choice([0.5, 1.0, 2.0, 4.0], n),
        "yaw": rng.uniform(-180, 180, n), "valid": valid,
        "correct": pa.array(np.where(valid, correct, False), mask=~valid),
        "top1_label": rng.choice(["cup", "switch"], n), "image_key": np.arange(n).astype(str),
        "topk_labels": pa.nulls(n, pa.list_(pa.string())), "topk_probs": pa.nulls(n, pa.list_(pa.float32())),
        "loss": rng.exponential(1.0, n),
    })


@pytest.mark.slow
def test_accuracies_over_a_million_rows_equal_exact_fractions() -> None:
    n = 1_000_000
    data = _synthetic(n, seed=3)
    summary = summarise(_results_connection(data), ["zoom", "yaw"])
    valid = data.column("valid").to_numpy(zero_copy_only=False)
    correct = data.column("correct").fill_null(False).to_numpy(zero_copy_only=False)
    assert summary.evaluated == n and summary.invalid == int((~valid).sum())
    exact = Fraction(int(correct.sum()), int(valid.sum()))
    assert summary.accuracy == float(exact)  # the overall figure is an exact ratio of counts

    objects = data.column("object").to_numpy(zero_copy_only=False)
    environments = data.column("environment").to_numpy(zero_copy_only=False)
    for i, obj in enumerate(summary.objects):
        for j, env in enumerate(summary.environments):
            cell = valid & (objects == obj) & (environments == env)
            want = Fraction(int((correct & cell).sum()), int(cell.sum()))
            assert summary.scene_count[i][j] == int(cell.sum())
            assert summary.scene_accuracy[i][j] == pytest.approx(float(want), rel=1e-15, abs=0)
    zoom = next(e for e in summary.effects if e.column == "zoom")
    zooms = data.column("zoom").to_numpy()
    for label, accuracy, count in zip(zoom.labels, zoom.accuracy, zoom.count):
        cell = valid & (zooms == float(label))
        assert count == int(cell.sum())
        assert accuracy == pytest.approx(float(Fraction(int((correct & cell).sum()), count)), rel=1e-15, abs=0)
    yaw = next(e for e in summary.effects if e.column == "yaw")  # binned: counts add up, accuracy exact
    assert sum(yaw.count) == int(valid.sum())


def test_summary_is_the_same_whatever_the_row_order() -> None:
    data = _synthetic(200_000, seed=4)
    shuffled = data.take(np.random.default_rng(0).permutation(len(data)))
    a = summarise(_results_connection(data), ["zoom"])
    b = summarise(_results_connection(shuffled), ["zoom"])
    assert (a.accuracy, a.invalid, a.scene_count) == (b.accuracy, b.invalid, b.scene_count)
    assert a.scene_accuracy == b.scene_accuracy
    assert [e.accuracy for e in a.effects] == [e.accuracy for e in b.effects]


# -- properties ------------------------------------------------------------------------------

PROPS = settings(max_examples=examples(60), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
finite = st.floats(allow_nan=False, allow_infinity=False)


@PROPS
@given(finite, finite, st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_any_finite_range_maps_the_unit_interval_inside_itself_monotonically(a, b, u, v) -> None:
    """Even ranges whose width overflows a float (e.g. [-1e308, 1e308]) stay finite and ordered."""
    if a == b:
        return
    r = Range(min(a, b), max(a, b))
    x, y = r.at(min(u, v)), r.at(max(u, v))
    assert math.isfinite(x) and r.low <= x <= y <= r.high
    mid = r.at(0.5)
    assert r.low <= mid <= r.high
    assert mid == pytest.approx(r.low / 2 + r.high / 2, rel=0, abs=1e-12 * max(abs(r.low), abs(r.high), 1e-300))


def sampling_spec(seed: int, zoom: tuple[float, float], el: tuple[float, float], scale: tuple[float, float],
                  policy: str) -> str:
    """The camera's zoom and elevation and the scale's factor over the ranges given, drawn 7 times."""
    return spec_toml("sampling", seed=seed, store=None, render={"resolution": 32, "samples": 1}, body=f"""\
[[controls]]
type = "camera"
zoom = {{ range = [{zoom[0]!r}, {zoom[1]!r}], log = true }}
elevation = {{ range = [{el[0]!r}, {el[1]!r}] }}

[[controls]]
type = "scale"
factor = {{ range = [{scale[0]!r}, {scale[1]!r}] }}

[policy]
type = "{policy}"
samples = 7
""")

positive = st.floats(1e-6, 1e6)
elevation = st.floats(-90.0, 90.0)


@settings(max_examples=examples(25), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.tuples(positive, positive), st.tuples(elevation, elevation), st.tuples(positive, positive),
       st.sampled_from(["random", "sobol"]), st.integers(0, 2**32))
def test_planned_values_stay_inside_declared_ranges_and_follow_the_seed(tmp_path_factory, zoom, el, scale,
                                                                        policy, seed) -> None:
    if len({*zoom}) < 2 or len({*el}) < 2 or len({*scale}) < 2:
        return
    from tests.helpers import plan_for

    folder = tmp_path_factory.mktemp("sampling")
    (zl, zh), (el_lo, el_hi), (sl, sh) = sorted(zoom), sorted(el), sorted(scale)
    body = sampling_spec(seed, (zl, zh), (el_lo, el_hi), (sl, sh), policy)
    loaded = load_spec(write_spec(folder, body))
    jobs = plan_for(loaded, "m").jobs
    assert len(jobs) == 7
    for job in jobs:
        camera, factor = job.values["camera"], job.values["scale"]["factor"]
        assert zl <= camera["zoom"] <= zh and el_lo <= camera["elevation"] <= el_hi and sl <= factor <= sh
        assert all(math.isfinite(v) for v in (camera["zoom"], camera["elevation"], factor))
    again = plan_for(load_spec(folder / "spec.toml"), "m").jobs
    assert [j.render_key for j in again] == [j.render_key for j in jobs]  # the seed decides everything


groups = st.lists(st.tuples(st.sampled_from(["a", "b", "c"]), st.booleans(), st.booleans()), min_size=1, max_size=40)


def _table(rows: list[tuple[str, bool, bool]], start: int = 0) -> pa.Table:
    return pa.table({
        "job": list(range(start, start + len(rows))), "object": [r[0] for r in rows],
        "environment": ["e"] * len(rows), "valid": [r[1] for r in rows],
        "correct": [r[2] if r[1] else None for r in rows], "top1_label": ["x"] * len(rows),
        "image_key": [str(i) for i in range(len(rows))], "topk_labels": pa.nulls(len(rows), pa.list_(pa.string())),
        "topk_probs": pa.nulls(len(rows), pa.list_(pa.float32())), "loss": [1.0] * len(rows),
    })


@settings(max_examples=examples(20), deadline=None)
@given(groups, groups, st.randoms(use_true_random=False))
def test_accuracy_of_a_concatenation_is_the_count_weighted_mean_and_ignores_order(first, second, rnd) -> None:
    both = first + second
    whole = summarise(_results_connection(_table(both)), [])
    parts = [summarise(_results_connection(_table(p)), []) for p in (first, second)]
    shuffled = list(both)
    rnd.shuffle(shuffled)
    assert summarise(_results_connection(_table(shuffled)), []).accuracy == whole.accuracy
    counted = [(p.accuracy, p.evaluated - p.invalid) for p in parts if p.accuracy is not None]
    if not counted:
        assert whole.accuracy is None
        return
    weighted = sum(Fraction(acc).limit_denominator(10**6) * n for acc, n in counted) / sum(n for _, n in counted)
    assert whole.accuracy == pytest.approx(float(weighted), rel=1e-12)
    assert whole.invalid == sum(p.invalid for p in parts)
    for i, obj in enumerate(whole.objects):  # per object too: each cell is its groups' weighted mean
        mine = [r for r in both if r[0] == obj and r[1]]
        if mine:
            assert whole.scene_accuracy[i][0] == pytest.approx(sum(r[2] for r in mine) / len(mine), rel=1e-12)
