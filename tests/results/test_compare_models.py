"""Several models in one spec: shared renders, per-model views, and the comparison views.

The synthetic stores here are written row by row, so each test knows the exact answer (fixed and
broken counts, McNemar's exact p-value from the binomial sum, Holm's adjustment); the tiny run
checks that a second model costs only inference, and the browser test that the panel draws.
"""

from __future__ import annotations

import json
import math
from datetime import datetime
from pathlib import Path
from typing import Any

import duckdb
import pyarrow as pa
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.results import connect
from sweep3d.results.compare import create_mcnemar
from sweep3d.spec.columns import MODELS_METADATA, PARAMETERS_METADATA
from tests.helpers import TINY_SPEC, TWO_MODELS, examples, write_spec

T0 = datetime(2024, 1, 1)


def mcnemar(b: int, c: int) -> float:
    """The exact two-sided McNemar p-value, by hand: twice the binomial tail at one half."""
    n = b + c
    if n == 0:
        return 1.0
    return min(1.0, 2 * sum(math.comb(n, k) for k in range(min(b, c) + 1)) / 2**n)


def make_store(folder: Path, answers: dict[str, list[bool]], levels: list[str], experiment: str = "e") -> Store:
    """A store with one job per entry of ``levels`` (the value of a control ``c_v``) and, per
    model, whether it was right on each job."""
    store = Store(folder / "store")
    jobs, predictions = [], []
    for model, correct in answers.items():
        for i, (right, level) in enumerate(zip(correct, levels)):
            key = f"{model}-{i}"
            jobs.append({"experiment": experiment, "job": i, "object": "obj", "environment": "env", "c_v": level,
                         "render_key": f"r{i}", "image_key": f"r{i}", "pred_key": key, "model": model})
            predictions.append({"pred_key": key, "image_key": f"r{i}", "created_at": T0, "valid": True,
                                "correct": right, "top1_label": "thing" if right else f"other-{model}",
                                "model": "whatever the first writer said"})
    table = pa.Table.from_pylist(jobs).replace_schema_metadata(
        {PARAMETERS_METADATA: json.dumps(["c_v"]).encode(), MODELS_METADATA: json.dumps(list(answers)).encode()})
    store.write_table_file(store.jobs_path(experiment), table)
    store.append("predictions", predictions)
    return store


def rows(con: duckdb.DuckDBPyConnection, sql: str, params: list | None = None) -> list[dict[str, Any]]:
    cursor = con.execute(sql, params or [])
    names = [d[0] for d in cursor.description]
    return [dict(zip(names, r)) for r in cursor.fetchall()]


def test_mcnemar_macro_equals_the_binomial_sum() -> None:
    con = duckdb.connect()
    create_mcnemar(con)
    for b, c in ((0, 0), (0, 1), (0, 5), (3, 10), (10, 3), (7, 7), (50, 70), (400, 460)):
        got = con.execute("SELECT mcnemar_p(?::BIGINT, ?::BIGINT)", [b, c]).fetchone()[0]
        assert got == pytest.approx(mcnemar(b, c), rel=1e-9, abs=1e-15), (b, c)


@settings(max_examples=examples(60), deadline=None)
@given(st.integers(0, 3000), st.integers(0, 3000))
def test_mcnemar_is_a_probability_for_any_counts(b: int, c: int) -> None:
    con = duckdb.connect()
    create_mcnemar(con)
    p = con.execute("SELECT mcnemar_p(?::BIGINT, ?::BIGINT)", [b, c]).fetchone()[0]
    assert 0.0 <= p <= 1.0 and math.isfinite(p)
    assert p == pytest.approx(con.execute("SELECT mcnemar_p(?::BIGINT, ?::BIGINT)", [c, b]).fetchone()[0])
    if b == c:
        assert p == 1.0


def test_fixed_broken_and_p_values_equal_a_hand_computation(tmp_path: Path) -> None:
    levels = ["x"] * 30 + ["y"] * 30
    old = [i % 3 != 0 for i in range(30)] + [True] * 30  # x: 20 right; y: all right
    new = [True] * 30 + [i % 2 == 0 for i in range(30)]  # x: all right (10 fixed); y: 15 broken
    con = connect(make_store(tmp_path, {"old": old, "new": new}, levels), "e")
    [pair] = rows(con, "SELECT * FROM model_agreement")
    assert (pair["model_a"], pair["model_b"], pair["n"]) == ("old", "new", 60)
    assert (pair["fixed"], pair["broken"]) == (10, 15)
    assert pair["p_value"] == pytest.approx(mcnemar(10, 15))
    assert pair["difference"] == pytest.approx((45 - 50) / 60)
    same = sum(a == b for a, b in zip(old, new))  # both right share "thing"; wrong answers differ by model
    assert pair["same_top1"] == pytest.approx(sum(a and b for a, b in zip(old, new)) / 60)
    observed = same / 60
    expected = (50 * 45 + 10 * 15) / 60**2
    assert pair["kappa"] == pytest.approx((observed - expected) / (1 - expected))

    per_level = {r["label"]: r for r in rows(con, "SELECT * FROM model_comparison WHERE parameter = 'c_v'")}
    assert (per_level["x"]["fixed"], per_level["x"]["broken"]) == (10, 0)
    assert (per_level["y"]["fixed"], per_level["y"]["broken"]) == (0, 15)
    assert per_level["x"]["accuracy_a"] == pytest.approx(20 / 30) and per_level["x"]["accuracy_b"] == 1.0
    assert per_level["y"]["p_value"] == pytest.approx(mcnemar(0, 15))

    regions = {r["label_a"]: r for r in rows(con, "SELECT * FROM model_regions WHERE parameter_a = 'c_v'")}
    tested = rows(con, "SELECT p_value FROM model_regions ORDER BY p_value")
    m = len(tested)  # Holm: the smallest p times the number of regions tested
    assert regions["y"]["p_holm"] == pytest.approx(min(1.0, m * mcnemar(0, 15)))
    assert regions["y"]["verdict"] == "worse" and regions["x"]["verdict"] == "better"

    changes = rows(con, "SELECT change, count(*) AS n FROM model_changes GROUP BY change ORDER BY change")
    assert changes == [{"change": "broken", "n": 15}, {"change": "fixed", "n": 10}]


def test_noise_is_not_called_a_regression(tmp_path: Path) -> None:
    """Two models that differ on a few jobs each way: no region is better or worse after Holm."""
    levels = [["a", "b", "c", "d"][i % 4] for i in range(80)]
    old = [i % 5 != 0 for i in range(80)]
    new = [(i % 5 != 0) != (i % 16 == 3) for i in range(80)]  # flips 5 jobs, both ways
    con = connect(make_store(tmp_path, {"old": old, "new": new}, levels), "e")
    verdicts = {r["verdict"] for r in rows(con, "SELECT verdict FROM model_regions")}
    assert verdicts == {"same"}


def test_results_show_one_model_and_results_all_every_model(tmp_path: Path) -> None:
    store = make_store(tmp_path, {"old": [True, False, False], "new": [True, True, True]}, ["x", "y", "z"])
    first = connect(store, "e")
    assert rows(first, "SELECT DISTINCT model FROM results") == [{"model": "old"}]
    assert first.execute("SELECT count(*) FROM results_all").fetchone()[0] == 6
    assert first.execute("SELECT sum(n_correct) FROM control_accuracy WHERE parameter = 'c_v'").fetchone()[0] == 1
    second = connect(store, "e", model="new")
    assert second.execute("SELECT sum(n_correct) FROM control_accuracy WHERE parameter = 'c_v'").fetchone()[0] == 3
    # the job names its model: a prediction row's own ``model`` is whatever its first writer called it
    assert {r["model"] for r in rows(second, "SELECT model FROM results_all")} == {"old", "new"}


def test_an_unknown_model_is_one_line(tmp_path: Path) -> None:
    make_store(tmp_path, {"old": [True], "new": [False]}, ["x"])
    spec = write_spec(tmp_path, TINY_SPEC.replace('name = "tiny"', 'name = "e"'))
    result = CliRunner().invoke(app, ["query", str(spec), "SELECT 1", "--model", "newer"])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == ["error: --model newer: the experiment's models are old, new"]


def test_plan_lists_each_model_and_says_renders_are_shared(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, TINY_SPEC.replace("[model]\nbatch_size = 8\n", TWO_MODELS))
    result = CliRunner().invoke(app, ["plan", str(spec)], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert "infer efficientnet-lite0" in result.output and "infer lite0-onnx" in result.output
    assert "2 models infer the same renders" in result.output


def test_models_framed_apart_get_renders_of_their_own(tmp_path: Path) -> None:
    """resolution = "model" with Lite0 (224²) and Lite2 (260²): each input size is rendered once."""
    two = TWO_MODELS.replace('name = "efficientnet-lite0"\nid = "lite0-onnx"\nbackend = "onnx"',
                             'name = "efficientnet-lite2"\nid = "lite2"')
    spec = write_spec(tmp_path, TINY_SPEC.replace("[model]\nbatch_size = 8\n", two)
                      .replace("resolution = 32", 'resolution = "model"'))
    result = CliRunner().invoke(app, ["plan", str(spec)], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    lines = {line.split("│")[1].strip(): line for line in result.output.splitlines() if line.startswith("│")}
    assert {"render (224²)", "render (260²)", "infer efficientnet-lite0", "infer lite2"} <= set(lines)
    assert "224²: efficientnet-lite0; 260²: lite2" in " ".join(result.output.split())


def test_adding_a_model_renders_nothing_and_infers_only_it(tiny_copy: Path) -> None:
    from sweep3d.runner.pipeline import run
    from tests.helpers import load_spec

    spec = tiny_copy / "spec.toml"
    spec.write_text(spec.read_text().replace("[model]\nbatch_size = 8\n", TWO_MODELS))
    result = run(load_spec(spec))
    done = {o.stage: o for o in result.outcomes}
    assert done["render"].computed == 0 and done["postprocess"].computed == 0
    assert done["infer efficientnet-lite0"].computed == 0 and done["infer efficientnet-lite0"].cached == 8
    assert done["infer lite0-onnx"].computed == 8
    con = connect(Store(tiny_copy / "store"), "tiny")
    counts = dict(con.execute("SELECT model, count(*) FROM results_all GROUP BY model").fetchall())
    assert counts == {"efficientnet-lite0": 8, "lite0-onnx": 8}
    # the same images: each job's image key is the same for both models (4 renders × 2 blurs)
    assert con.execute("SELECT count(DISTINCT render_key), count(DISTINCT image_key) FROM results_all").fetchone() \
        == (4, 8)
    [pair] = rows(con, "SELECT * FROM model_agreement")
    assert pair["n"] == 8
    assert pair["fixed"] + pair["broken"] == con.execute(
        "SELECT count(*) FROM model_pairs WHERE correct_a <> correct_b").fetchone()[0]

    output = CliRunner().invoke(app, ["compare", str(spec)], env={"COLUMNS": "200"}).output
    assert "lite0-onnx against efficientnet-lite0" in output and "McNemar p" in output


@pytest.mark.browser
def test_comparison_panel_draws_in_chromium(tiny_copy: Path, chromium) -> None:
    from sweep3d.report import write_report
    from tests.helpers import assert_clean, load_spec, open_page

    spec = tiny_copy / "spec.toml"
    spec.write_text(spec.read_text().replace("[model]\nbatch_size = 8\n", TWO_MODELS))
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output
    path = write_report(load_spec(spec))
    with open_page(chromium, path) as (page, events):
        assert page.locator("#compare").count() == 1
        assert "lite0-onnx against efficientnet-lite0" in page.inner_text("#compare")
        traces = page.evaluate("document.getElementById('fig-compare-0').data.map(t => t.name)")
        assert traces == ["efficientnet-lite0", "lite0-onnx"]
        assert page.evaluate("document.querySelectorAll('#fig-compare-0 svg.main-svg').length") > 0
        assert_clean(path, events)
