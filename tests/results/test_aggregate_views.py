"""The aggregate SQL views: levels and bins, Wilson intervals, failure modes, variance explained.

Stores here are written row by row (jobs table and prediction segments) so each test knows the
exact answer; ``test_query_sees_the_views`` runs them on the real tiny run through the CLI.
"""

from __future__ import annotations

import json
import math
import tempfile
from datetime import datetime
from pathlib import Path
from typing import Any

import duckdb
import pyarrow as pa
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

import sweep3d.results.summary as summary_module
from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.results import (
    MACROS,
    VIEWS,
    connect,
    nearest_miss_region,
    register_views,
    stored_summary,
    summarise,
    weakest_regions,
    wilson_interval,
)
from sweep3d.results.compare import COMPARE_VIEWS
from sweep3d.results.detection import DETECTION_VIEWS
from sweep3d.results.summary import summary_path
from sweep3d.results.task_views import TASK_VIEWS
from sweep3d.results.views import BINS, NOT_APPLIED
from tests.helpers import examples, make_store, rows_of


def wilson(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def test_wilson_macros_match_the_formula_and_published_values() -> None:
    con = duckdb.connect()
    assert register_views(con) is False  # no results: only the macros
    for k, n in ((0, 10), (5, 10), (10, 10), (3, 7), (1, 1000)):
        low, high = con.execute("SELECT wilson_low(?, ?), wilson_high(?, ?)", [k, n, k, n]).fetchone()
        assert (low, high) == pytest.approx(wilson(k, n), abs=1e-12)
    # Newcombe (1998), table I: 0/10 → 0.0000–0.2775, 5/10 → 0.2366–0.7634 (z = 1.96)
    published = con.execute("SELECT round(wilson_high(0, 10), 4), round(wilson_low(5, 10), 4)").fetchone()
    assert published == (0.2775, 0.2366)
    assert con.execute("SELECT wilson_low(0, 0), wilson_high(0, 0)").fetchone() == (None, None)


def _assert_exact_at_the_edges(k: int, n: int, low: float, high: float, accuracy: float | None = None) -> None:
    p = k / n if accuracy is None else accuracy
    assert 0.0 <= low <= p <= high <= 1.0, (k, n, low, p, high)
    assert (low == 0.0) == (k == 0) and (high == 1.0) == (k == n), (k, n, low, high)


@settings(max_examples=examples(100), deadline=None)
@given(st.integers(1, 10**9).flatmap(lambda n: st.tuples(st.integers(0, n), st.just(n)))
       | st.integers(1, 10**6).flatmap(lambda n: st.sampled_from([(0, n), (n, n), (1, n), (n - 1, n)])))
def test_wilson_interval_holds_its_accuracy_and_is_exact_at_the_edges(case: tuple[int, int]) -> None:
    k, n = case
    _assert_exact_at_the_edges(k, n, *wilson_interval(k, n))


@settings(max_examples=examples(25), deadline=None)
@given(st.lists(st.integers(1, 60).flatmap(lambda n: st.tuples(st.integers(0, n), st.just(n))
                                          | st.sampled_from([(0, n), (n, n)])), min_size=1, max_size=6))
def test_control_accuracy_and_failure_modes_intervals_hold_their_accuracy(levels: list[tuple[int, int]]) -> None:
    """Through the views, as the report and the failure modes read them: 0 of 48 gave a low end of
    6.4e-18, above its accuracy of 0."""
    rows = [{"c_level": f"L{i}", "correct": j < k} for i, (k, n) in enumerate(levels) for j in range(n)]
    with tempfile.TemporaryDirectory() as folder:
        con = make_store(Path(folder), rows)
        found = rows_of(con, "SELECT level, n, n_correct, accuracy, wilson_low, wilson_high FROM control_accuracy "
                             "WHERE parameter = 'c_level' ORDER BY level")
        modes = rows_of(con, "FROM failure_modes(min_count := 1)")
    assert [(r["n_correct"], r["n"]) for r in found] == levels
    for r in found + modes:
        _assert_exact_at_the_edges(r["n_correct"], r["n"], r["wilson_low"], r["wilson_high"], r["accuracy"])


def test_no_successes_in_48_is_a_low_end_of_exactly_0_in_every_view(tmp_path: Path) -> None:
    rows = [{"c_a": "bad", "correct": False} for _ in range(48)] + [{"c_a": "good", "correct": True} for _ in range(48)]
    con = make_store(tmp_path, rows)
    bad = "parameter = 'c_a' AND label = 'bad'"
    assert con.execute(f"SELECT wilson_low, accuracy FROM control_accuracy WHERE {bad}").fetchone() == (0.0, 0.0)
    assert con.execute("SELECT wilson_high FROM control_accuracy WHERE parameter = 'c_a' AND label = 'good'"
                       ).fetchone() == (1.0,)
    assert con.execute("SELECT wilson_low, accuracy FROM failure_modes(min_count := 10) WHERE region = 'c_a = bad'"
                       ).fetchone() == (0.0, 0.0)
    assert wilson_interval(0, 48)[0] == 0.0 and wilson_interval(48, 48)[1] == 1.0


def test_levels_keep_value_order_bin_many_numbers_and_mark_not_applied(tmp_path: Path) -> None:
    rows = []
    for i in range(40):
        rows.append({"c_size": [5.0, 10.0, 45.0][i % 3],  # numeric order, not string order
                     "c_angle": float(i * 2.5),  # 40 values in 0..97.5: binned
                     "c_name": ["b", "a"][i % 2],
                     "c_only": 1.0 if i < 30 else None,  # a control limited to some scenes
                     "correct": i % 4 == 0})
    con = make_store(tmp_path, rows)
    params = {r["parameter"]: r for r in rows_of(con, "FROM control_parameters")}
    assert list(params) == ["object", "environment", "c_size", "c_angle", "c_name", "c_only"]
    assert [params[p]["levels"] for p in params] == [1, 1, 3, 10, 2, 2]
    assert params["c_angle"]["binned"] and not params["c_size"]["binned"]

    labels = {}
    for r in rows_of(con, "SELECT parameter, label FROM control_accuracy ORDER BY position, level"):
        labels.setdefault(r["parameter"], []).append(r["label"])
    assert labels["c_size"] == ["5", "10", "45"]
    assert labels["c_name"] == ["a", "b"]
    assert labels["c_only"] == ["1", NOT_APPLIED]
    assert len(labels["c_angle"]) == BINS
    assert labels["c_angle"][0] == "0–9.8" and labels["c_angle"][-1] == "87.8–97.5"  # edges to 2 digits of the width

    counts = dict(con.execute(
        "SELECT label, n FROM control_accuracy WHERE parameter = 'c_angle' ORDER BY level").fetchall())
    assert sum(counts.values()) == 40 and set(counts.values()) == {4}  # the maximum falls in the last bin


def test_accuracy_counts_valid_results_only(tmp_path: Path) -> None:
    rows = [{"c_x": 1, "correct": True}, {"c_x": 1, "correct": False}, {"c_x": 1, "correct": None, "valid": False},
            {"c_x": 2, "correct": True}]
    con = make_store(tmp_path, rows)
    found = {r["label"]: r for r in rows_of(con, "FROM control_accuracy WHERE parameter = 'c_x'")}
    assert (found["1"]["n"], found["1"]["n_correct"], found["1"]["accuracy"]) == (2, 1, 0.5)
    assert (found["1"]["wilson_low"], found["1"]["wilson_high"]) == pytest.approx(wilson(1, 2))
    assert (found["2"]["n"], found["2"]["accuracy"]) == (1, 1.0)


def _grid(correct, repeat: int = 5, b_values: tuple[int, ...] = (0, 1, 2)) -> list[dict[str, Any]]:
    return [{"c_a": a, "c_b": b, "correct": correct(a, b)} for a in (0, 1) for b in b_values for _ in range(repeat)]


def test_variance_explained_separates_main_effects_from_interactions(tmp_path: Path) -> None:
    con = make_store(tmp_path / "main", _grid(lambda a, b: a == 1))
    shares = {r["effect"]: r for r in rows_of(con, "FROM variance_explained")}
    assert shares["c_a"]["eta2"] == pytest.approx(1.0)
    assert shares["c_b"]["eta2"] == pytest.approx(0.0)
    assert shares["c_a × c_b"]["eta2"] == pytest.approx(0.0)
    assert shares["c_a"]["kind"] == "main" and shares["c_a × c_b"]["kind"] == "interaction"
    assert shares["c_a"]["df"] == 1 and shares["c_b"]["df"] == 2 and shares["c_a × c_b"]["df"] == 2
    assert 0 < shares["c_a"]["eta2_adjusted"] <= 1.0

    con = make_store(tmp_path / "xor", _grid(lambda a, b: a != b, b_values=(0, 1)))
    shares = {r["effect"]: r["eta2"] for r in rows_of(con, "FROM variance_explained")}
    assert shares["c_a"] == pytest.approx(0.0, abs=1e-12) and shares["c_b"] == pytest.approx(0.0, abs=1e-12)
    assert shares["c_a × c_b"] == pytest.approx(1.0)


def test_failure_modes_need_support_rank_by_upper_bound_and_list_pairs_only_when_worse(tmp_path: Path) -> None:
    rows = []
    rows += [{"c_a": "bad", "c_b": b, "correct": i < 2} for i in range(20) for b in ["x"]]  # 10 %, n = 20
    rows += [{"c_a": "tiny", "c_b": "x", "correct": False} for _ in range(3)]  # 0 %, n = 3
    rows += [{"c_a": "good", "c_b": "x", "correct": True} for _ in range(40)]
    rows += [{"c_a": "good", "c_b": "y", "correct": i < 8} for i in range(20)]  # 40 %: bad only with b = y
    con = make_store(tmp_path, rows)
    overall = con.execute("SELECT avg(correct::DOUBLE) FROM results WHERE valid").fetchone()[0]

    modes = rows_of(con, "FROM failure_modes(min_count := 5)")
    regions = [m["region"] for m in modes]
    assert "c_a = tiny" not in regions  # 3 results: too few
    assert regions[0] == "c_a = bad"
    assert all(m["n"] >= 5 and m["accuracy"] < overall for m in modes)
    highs = [m["wilson_high"] for m in modes]
    assert highs == sorted(highs)
    assert "c_b = y" in regions
    pairs = [m for m in modes if m["size"] == 2]
    assert all(m["parameter_b"] is not None for m in pairs)
    for m in pairs:  # each pair is confidently worse than both of its values alone
        singles = dict(con.execute(
            "SELECT parameter || '=' || label, accuracy FROM control_accuracy").fetchall())
        assert m["wilson_high"] < singles[f"{m['parameter_a']}={m['label_a']}"]
        assert m["wilson_high"] < singles[f"{m['parameter_b']}={m['label_b']}"]
    assert len(rows_of(con, "FROM failure_modes(min_count := 3)")) > len(modes)


def test_per_object_sensitivity_and_confusions(tmp_path: Path) -> None:
    rows = []
    for yaw in (0, 90):
        for i in range(10):
            rows.append({"object": "mug", "c_yaw": yaw, "c_blur": i % 2, "correct": yaw == 0,
                         "prediction": "mug" if yaw == 0 else ("cup" if i < 7 else "bowl")})
            rows.append({"object": "ball", "c_yaw": yaw, "c_blur": i % 2, "correct": i % 2 == 0,
                         "prediction": "ball" if i % 2 == 0 else "egg"})
    con = make_store(tmp_path, rows)
    found = {(r["object"], r["parameter"]): r for r in rows_of(con, "FROM object_sensitivity")}
    mug_yaw = found[("mug", "c_yaw")]
    assert mug_yaw["eta2"] == pytest.approx(1.0)
    assert (mug_yaw["accuracy_min"], mug_yaw["worst_level"], mug_yaw["accuracy_max"], mug_yaw["best_level"]) == (
        0.0, "90", 1.0, "0")
    assert found[("ball", "c_blur")]["eta2"] == pytest.approx(1.0)
    assert found[("ball", "c_yaw")]["accuracy_range"] == pytest.approx(0.0)
    assert ("mug", "object") not in found

    confusions = rows_of(con, "FROM object_confusions WHERE object = 'mug'")
    assert [(c["prediction"], c["n"], c["rank"]) for c in confusions] == [("cup", 7, 1), ("bowl", 3, 2)]
    assert confusions[0]["share"] == pytest.approx(0.7)


def _effect_sizes(groups: list[tuple[int, int]]) -> tuple[float, float]:
    """(eta², epsilon²) of correct over groups given as (n, n_correct), by hand."""
    n, k = sum(g[0] for g in groups), sum(g[1] for g in groups)
    p = k / n
    between = sum(size * (right / size - p) ** 2 for size, right in groups)
    total = n * p * (1 - p)
    df = len(groups) - 1
    return between / total, max(between - df * (total - between) / (n - df - 1), 0) / total


def test_object_sensitivity_leaves_out_levels_with_too_few_results(tmp_path: Path) -> None:
    rows = []
    for x, size, right in (("a", 20, 10), ("b", 20, 10), ("c", 2, 0)):  # c: 2 images, both wrong
        rows += [{"object": "mug", "c_x": x, "c_y": i % 2, "correct": i < right} for i in range(size)]
    con = make_store(tmp_path, rows)
    found = {r["parameter"]: r for r in rows_of(con, "FROM object_sensitivity WHERE object = 'mug'")}
    x = found["c_x"]  # at the default of 10 results per level, c is left out: a and b are alike
    assert (x["levels"], x["n"], x["worst_level"], x["worst_n"], x["best_n"]) == (2, 40, "a", 20, 20)
    assert x["accuracy_range"] == 0 and x["eta2"] == 0 and x["eta2_adjusted"] == 0
    assert rows_of(con, "FROM object_sensitivity") == rows_of(con, "FROM object_sensitivity(min_count := 10)")

    lowered = {r["parameter"]: r for r in rows_of(con, "FROM object_sensitivity(min_count := 2)")}["c_x"]
    assert (lowered["levels"], lowered["worst_level"], lowered["accuracy_min"], lowered["worst_n"]) == (3, "c", 0, 2)
    eta2, epsilon2 = _effect_sizes([(20, 10), (20, 10), (2, 0)])
    assert lowered["eta2"] == pytest.approx(eta2) and eta2 > 0.04
    assert lowered["eta2_adjusted"] == pytest.approx(epsilon2) == 0  # two images explain nothing beyond chance

    few = [{"object": "cup", "c_x": x, "correct": x == "a"} for x in ("a", "b") for _ in range(3)] + rows
    con = make_store(tmp_path / "few", few)  # the cup has 3 results per level: no level qualifies at 10
    assert not [r for r in rows_of(con, "FROM object_sensitivity") if r["object"] == "cup"]
    assert {r["parameter"] for r in rows_of(con, "FROM object_sensitivity(min_count := 3)")
            if r["object"] == "cup"} == {"c_x"}


def test_object_sensitivity_beyond_chance_is_the_aggregate_panel_s(tmp_path: Path) -> None:
    groups = [(12, 3), (12, 6), (12, 10)]
    rows = [{"object": "mug", "c_x": x, "c_y": i % 3, "correct": i < right}
            for x, (size, right) in enumerate(groups) for i in range(size)]
    con = make_store(tmp_path, rows)
    sensitivity = {r["parameter"]: r for r in rows_of(con, "FROM object_sensitivity")}
    shares = {r["effect"]: r for r in rows_of(con, "FROM variance_explained WHERE kind = 'main'")}
    eta2, epsilon2 = _effect_sizes(groups)
    assert 0 < epsilon2 < eta2
    for name in ("c_x", "c_y"):  # one object: its sensitivity is the experiment's main effect
        assert sensitivity[name]["eta2_adjusted"] == pytest.approx(shares[name]["eta2_adjusted"], rel=1e-12, abs=1e-15)
        assert sensitivity[name]["eta2"] == pytest.approx(shares[name]["eta2"], rel=1e-12, abs=1e-15)
    assert sensitivity["c_x"]["eta2_adjusted"] == pytest.approx(epsilon2)
    assert sensitivity["c_x"]["eta2"] == pytest.approx(eta2)
    (value,) = con.execute("SELECT epsilon_squared(?, ?, ?, ?, ?)", [4.0, 2, 10.0, 30, 14.0]).fetchone()
    assert value == pytest.approx((4 - 2 * 10 / 30) / 14)  # the one formula both read


def _binomial_cdf(k: int, n: int, p: float) -> float:
    return sum(math.comb(n, j) * p**j * (1 - p) ** (n - j) for j in range(k + 1))


def _hypergeometric_cdf(k: int, draws: int, successes: int, total: int) -> float:
    return sum(math.comb(successes, j) * math.comb(total - successes, draws - j)
               for j in range(k + 1)) / math.comb(total, draws)


def test_failure_modes_test_each_value_against_the_rest_of_its_parameter(tmp_path: Path) -> None:
    rows = []
    for a, size, right in (("far", 20, 2), ("near", 20, 13), ("good", 60, 60)):
        rows += [{"c_a": a, "correct": i < right} for i in range(size)]
    con = make_store(tmp_path, rows)
    modes = {m["region"]: m for m in rows_of(con, "FROM failure_modes(min_count := 10)")}
    assert set(modes) == {"c_a = far", "c_a = near"}  # good is above the rest: not listed, but tested
    near, far = modes["c_a = near"], modes["c_a = far"]
    # Fisher's exact test, one-sided, against the other 80 results (73 right for far, 62 for near)
    p_far, p_near = _hypergeometric_cdf(2, 20, 75, 100), _hypergeometric_cdf(13, 20, 75, 100)
    assert far["p_value"] == pytest.approx(p_far, rel=1e-9) and near["p_value"] == pytest.approx(p_near, rel=1e-9)
    assert (far["n_rest"], far["accuracy_rest"], far["test"]) == (80, pytest.approx(73 / 80), "fisher")
    assert far["difference"] == pytest.approx(0.1 - 73 / 80)
    assert far["difference_low"] < far["difference"] < far["difference_high"] < 0
    # Benjamini–Hochberg over the three values of 10 or more results (good's p-value is 1)
    assert far["q_value"] == pytest.approx(3 * p_far, rel=1e-9)
    assert near["q_value"] == pytest.approx(min(1.0, 3 / 2 * p_near), rel=1e-9)
    assert far["significant"] is True and near["significant"] is (near["q_value"] < 0.05)
    # the earlier view's numbers stay: a binomial test against the overall 75 %, Holm-adjusted
    assert far["p_overall"] == pytest.approx(_binomial_cdf(2, 20, 0.75), rel=1e-9)
    assert far["p_holm_overall"] == pytest.approx(3 * _binomial_cdf(2, 20, 0.75), rel=1e-9)
    for k, n, p in ((0, 5, 0.3), (3, 10, 0.7), (9, 10, 0.95), (10, 10, 0.5)):
        (value,) = con.execute("SELECT binomial_cdf(?, ?, ?)", [k, n, p]).fetchone()
        assert value == pytest.approx(_binomial_cdf(k, n, p), rel=1e-9)
    for k, draws, successes, total in ((0, 5, 10, 20), (3, 10, 12, 30), (4, 4, 10, 12), (2, 8, 9, 12)):
        (value,) = con.execute("SELECT hypergeometric_cdf(?, ?, ?, ?)", [k, draws, successes, total]).fetchone()
        assert value == pytest.approx(_hypergeometric_cdf(k, draws, successes, total), rel=1e-9)

    summary = summarise(con, ["c_a"])  # the printed "fails most at" names only the significant one
    (region,) = weakest_regions(summary)
    assert (region.column, region.label, region.count, region.count_rest) == ("c_a", "far", 20, 80)
    assert region.q_value == pytest.approx(far["q_value"]) and summary.gap is None
    rows = [{"c_a": a, "correct": i < right} for a, right in (("near", 13), ("good", 16)) for i in range(20)]
    noise = summarise(make_store(tmp_path / "noise", rows), ["c_a"])
    assert weakest_regions(noise) == []
    gap = nearest_miss_region(noise)  # no failure mode, but the nearest miss is said, with its interval
    assert (gap.label, gap.accuracy, gap.accuracy_rest) == ("near", 0.65, 0.8) and gap.difference_low < -0.15


def test_half_hidden_halves_accuracy_and_is_named_with_a_paired_test(tmp_path: Path) -> None:
    """The audit's 48-job case: hiding half the object drops accuracy from 16/24 to 4/24 on the
    same 24 poses. Against the overall accuracy (which includes it) Holm said nothing; against the
    rest of its parameter, on the pairs, it is a failure mode."""
    rows = []
    for pose in range(24):
        rows.append({"hide": "none", "yaw": 15 * pose, "correct": pose < 16})
        rows.append({"hide": "half", "yaw": 15 * pose, "correct": pose < 4})
    con = make_store(tmp_path, rows)
    modes = {m["region"]: m for m in rows_of(con, "FROM failure_modes(min_count := 2)")}
    half = modes["hide = half"]
    assert half["test"] == "mcnemar" and half["significant"]
    assert half["p_value"] == pytest.approx(0.5 ** 12)  # 12 discordant pairs, all against half
    assert half["difference"] == pytest.approx(4 / 24 - 16 / 24)
    assert half["difference_low"] < -0.5 < half["difference_high"] < -0.2
    assert half["p_holm_overall"] > 0.05  # what the old view said: nothing
    (region,) = weakest_regions(summarise(con, ["hide", "yaw"]))
    assert (region.column, region.label) == ("hide", "half")
    unpaired = make_store(tmp_path / "unpaired", [{**r, "yaw": i} for i, r in enumerate(rows)])
    half = {m["region"]: m for m in rows_of(unpaired, "FROM failure_modes(min_count := 2)")}["hide = half"]
    assert half["test"] == "fisher" and half["p_value"] == pytest.approx(_hypergeometric_cdf(4, 24, 20, 48))
    assert half["significant"]


def test_a_control_is_compared_only_where_it_applies(tmp_path: Path) -> None:
    """c applies in one environment only (its values equally good there); the other environment is
    easier. Its values must not be named against results where c does not apply."""
    rows = [{"environment": "hard", "c_c": value, "correct": i % 2 == 0} for value in ("x", "y") for i in range(40)]
    rows += [{"environment": "easy", "correct": i % 10 != 0} for i in range(80)]  # c not applied
    con = make_store(tmp_path, rows)
    modes = rows_of(con, "FROM failure_modes(min_count := 10)")
    assert not [m for m in modes if "c_c" in (m["parameter_a"], m["parameter_b"])]
    assert {m["region"] for m in modes if m["significant"]} == {"environment = hard"}


def test_mcnemar_is_oriented_by_value_even_where_two_values_print_alike(tmp_path: Path) -> None:
    rows = []
    for pose in range(24):  # the larger value is right 4 times in 24, the smaller 20: 16 pairs against it
        rows.append({"c_z": 1.00001, "yaw": pose, "correct": pose < 20})
        rows.append({"c_z": 1.00002, "yaw": pose, "correct": pose < 4})
    con = make_store(tmp_path, rows)
    modes = [m for m in rows_of(con, "FROM failure_modes(min_count := 2)") if m["parameter_a"] == "c_z"]
    assert [(m["level_a"], m["test"], m["significant"]) for m in modes] == [(1, "mcnemar", True)]
    assert modes[0]["p_value"] == pytest.approx(0.5 ** 16)


def test_where_no_value_differs_nothing_is_named_in_95_percent_of_seeds() -> None:
    """A null model (every result right with the same chance, whatever the values) over three
    crossed parameters: the false discovery rate over values and pairs keeps the chance of naming
    any region at 5 % or less."""
    import random

    con = duckdb.connect()
    con.register("cases", pa.Table.from_pylist(_null_rows(random.Random(0))))
    con.execute("CREATE VIEW jobs AS SELECT * EXCLUDE (correct) FROM cases")
    con.execute("CREATE VIEW results AS SELECT *, true AS valid FROM cases")
    assert register_views(con, ["c_a", "c_b", "c_c"])
    named = 0
    seeds = 60
    for seed in range(seeds):
        con.register("cases", pa.Table.from_pylist(_null_rows(random.Random(seed))))
        named += con.execute("SELECT count(*) > 0 FROM failure_modes(min_count := 5) WHERE significant"
                             ).fetchall()[0][0]
    assert named <= 0.05 * seeds


def _null_rows(rng: Any) -> list[dict[str, Any]]:
    """96 results, 2 × 3 × 4 values crossed, 4 each, right with probability 0.7."""
    values = [(a, b, c) for a in "xy" for b in "uvw" for c in range(4) for _ in range(4)]
    return [{"job": i, "object": "o", "environment": "e", "c_a": a, "c_b": b, "c_c": c, "correct": rng.random() < 0.7}
            for i, (a, b, c) in enumerate(values)]


def test_views_come_with_every_connection_and_summary_reads_them(tmp_path: Path) -> None:
    con = make_store(tmp_path, _grid(lambda a, b: a == 1))
    present = {r[0] for r in con.execute("SELECT view_name FROM duckdb_views() WHERE NOT internal").fetchall()}
    assert set(VIEWS) - {"part_visibility", *DETECTION_VIEWS, *COMPARE_VIEWS, *TASK_VIEWS} <= present
    assert not set(DETECTION_VIEWS) & present  # only for a detector (tests/stages/infer/test_detection_eval.py)
    assert "part_visibility" not in present  # only with a UV pass (tests/results/test_part_visibility.py)
    assert not set(TASK_VIEWS) & present  # only with their columns (tests/results/test_tasks_report.py)
    assert not set(COMPARE_VIEWS) & present  # only with several models (tests/results/test_compare_models.py)
    macros = {r[0] for r in con.execute("SELECT function_name FROM duckdb_functions() WHERE function_type IN "
                                        "('macro', 'table_macro')").fetchall()}
    assert set(MACROS) <= macros
    assert register_views(con) is True  # idempotent

    summary = summarise(con, ["c_a", "c_b"])
    effect = {e.column: e for e in summary.effects}
    assert effect["c_a"].labels == ["0", "1"] and effect["c_a"].accuracy == [0.0, 1.0]
    assert effect["c_a"].count == [15, 15]
    assert effect["c_a"].high[0] == pytest.approx(wilson(0, 15)[1])

    bare = connect(Store(tmp_path / "store"))  # no experiment: no results, no views over them
    assert not {r[0] for r in bare.execute("SELECT view_name FROM duckdb_views() WHERE NOT internal").fetchall()} & set(
        VIEWS)


#: control_levels as it was written before it ranked each distinct level once: every
#: (result, parameter) row ranked and labelled on its own (the reference for the levels).
PER_ROW_LEVELS = f"""
    WITH placed AS (
        SELECT v.*, s.lo, s.width, s.digits,
               CASE WHEN s.binned AND v.number IS NOT NULL
                    THEN least(floor((v.number - s.lo) / s.width), {BINS - 1})::INTEGER END AS bin
        FROM control_values v JOIN control_stats s USING (parameter, position))
    SELECT job, object, environment, valid, counted, correct, parameter, position,
           (dense_rank() OVER (PARTITION BY parameter ORDER BY raw IS NULL, coalesce(bin::DOUBLE, number),
                               CASE WHEN bin IS NULL THEN raw END) - 1)::INTEGER AS level,
           CASE WHEN raw IS NULL THEN '{NOT_APPLIED}'
                WHEN bin IS NOT NULL THEN level_number_label(round(lo + bin * width, digits)) || '–'
                                          || level_number_label(round(lo + (bin + 1) * width, digits))
                WHEN number IS NOT NULL THEN level_number_label(number)
                ELSE raw END AS label
    FROM placed"""


def _varied_rows(n: int, seed: int = 0) -> list[dict[str, Any]]:
    """Results over every kind of parameter: few integers, many floats (binned) with gaps and
    jobs where the control does not apply, 0.0 beside -0.0, strings with an empty one, booleans."""
    import random

    rng = random.Random(seed)
    rows = []
    for i in range(n):
        rows.append({"object": rng.choice(["mug", "ball"]), "environment": rng.choice(["white", "forest"]),
                     "c_int": rng.randrange(4), "c_float": None if i % 9 == 0 else rng.choice([-90.0, 90.0]) * rng.random(),
                     "c_zero": rng.choice([0.0, -0.0, 1.5]), "c_str": rng.choice(["a", "b", "", None]),
                     "c_many": rng.randrange(20), "c_bool": rng.random() < 0.5, "c_tiny": rng.randrange(14) / 2000,
                     "correct": rng.random() < 0.6, "valid": rng.random() > 0.05})
    return rows


def test_levels_ranked_once_per_level_are_the_levels_of_ranking_every_row(tmp_path: Path) -> None:
    con = make_store(tmp_path, _varied_rows(400))
    columns = "job, object, environment, valid, counted, correct, parameter, position, level, label"
    ranked_once = con.execute(f"SELECT {columns} FROM control_levels ORDER BY job, position").fetchall()
    per_row = con.execute(f"SELECT {columns} FROM ({PER_ROW_LEVELS}) ORDER BY job, position").fetchall()
    assert ranked_once == per_row
    assert {r[0] for r in con.execute("DESCRIBE control_levels").fetchall()} == {*columns.split(", "), "value", "absent"}
    assert con.execute("SELECT bool_and(absent = (label = ?)) FROM control_levels", [NOT_APPLIED]).fetchone()[0]
    labels = dict(con.execute("SELECT parameter, list(DISTINCT label ORDER BY label) FROM control_levels "
                              "WHERE parameter IN ('c_zero', 'c_str') GROUP BY parameter").fetchall())
    assert labels["c_zero"] == ["0", "1.5"]  # 0.0 and -0.0 are two levels, both labelled 0, as before
    assert labels["c_str"] == ["", NOT_APPLIED, "a", "b"]


def test_object_sensitivity_names_the_first_level_of_a_tie_whatever_duckdb_s_threads(tmp_path: Path) -> None:
    rows = [{"object": "mug", "c_x": x, "correct": x in (1, 2)} for x in (0, 1, 2, 3) for _ in range(4)]
    con = make_store(tmp_path, rows)
    answers = set()
    sql = "SELECT parameter, worst_level, best_level FROM object_sensitivity(min_count := 4)"
    for threads in (1, 4):
        con.execute(f"SET threads = {threads}")
        answers.add(tuple(con.execute(sql).fetchall()))
    assert len(answers) == 1
    (row,) = [r for r in answers.pop() if r[0] == "c_x"]
    assert row[1:] == ("0", "1")  # worst: 0 and 3 tie at 0 %; best: 1 and 2 at 100 %


def test_summary_reads_results_once_and_leaves_the_views_answering_the_same(tmp_path: Path) -> None:
    con = make_store(tmp_path, _varied_rows(200))
    before = {view: con.execute(f"FROM {view}").fetchall() for view in ("results", "control_accuracy", "scene_accuracy")}
    first = summarise(con, ["c_int", "c_float", "c_str"])
    assert con.execute("SELECT count(*) FROM duckdb_tables() WHERE table_name = 'report_results'").fetchone()[0] == 1
    assert {view: con.execute(f"FROM {view}").fetchall() for view in before} == before
    assert summarise(con, ["c_int", "c_float", "c_str"]) == first == summarise(
        connect(Store(tmp_path / "store"), "e"), ["c_int", "c_float", "c_str"])
    assert [e.column for e in first.effects] == ["c_int", "c_float", "c_str"]


def _count_summaries(monkeypatch) -> list[int]:
    calls = [0]
    real = summary_module.summarise

    def counted(*args, **kwargs):
        calls[0] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(summary_module, "summarise", counted)
    return calls


def test_a_stored_summary_is_the_summary_and_an_unchanged_store_gives_it_again(tmp_path: Path, monkeypatch) -> None:
    make_store(tmp_path, _varied_rows(300))
    store, columns = Store(tmp_path / "store"), ["c_int", "c_float", "c_str", "c_zero"]
    computed = summarise(connect(store, "e"), columns)
    calls = _count_summaries(monkeypatch)
    assert stored_summary(store, "e", columns) == computed and calls[0] == 1
    assert summary_path(store, "e").exists()
    again = stored_summary(Store(tmp_path / "store"), "e", columns)
    assert again == computed and calls[0] == 1  # read back: the same numbers, not computed
    assert repr(again) == repr(computed)
    assert stored_summary(store, "e", columns[:2]) == summarise(connect(store, "e"), columns[:2]) and calls[0] == 2
    assert stored_summary(store, "e", columns, failure_limit=3).failures == computed.failures[:3] and calls[0] == 3


def test_a_new_segment_a_new_plan_or_a_damaged_file_computes_the_summary_again(tmp_path: Path, monkeypatch) -> None:
    rows = _varied_rows(100)
    make_store(tmp_path, rows)
    store, columns = Store(tmp_path / "store"), ["c_int"]
    first = stored_summary(store, "e", columns)
    calls = _count_summaries(monkeypatch)

    # a new prediction segment: computed again, whether it changes the numbers (an earlier row of
    # a key, which the views show instead) or not (a later row)
    key = "k0"
    store.append("predictions", [{"pred_key": key, "image_key": key, "created_at": datetime(2030, 1, 1),
                                  "valid": True, "correct": True, "top1_label": "thing", "topk": [0],
                                  "topk_labels": ["thing"], "topk_probs": [0.9], "loss": 1.0}])
    assert stored_summary(store, "e", columns) == first and calls[0] == 1
    store.append("predictions", [{"pred_key": "k1", "image_key": "k1", "created_at": datetime(2020, 1, 1),
                                  "valid": False, "correct": None, "top1_label": "thing", "topk": [0],
                                  "topk_labels": ["thing"], "topk_probs": [0.9], "loss": 1.0}])
    changed = stored_summary(store, "e", columns)
    assert calls[0] == 2 and changed.invalid == first.invalid + (1 if rows[1]["valid"] else 0)
    assert changed == summarise(connect(store, "e"), columns)

    # the plan written again with other jobs
    make_store(tmp_path, rows[:50])
    assert stored_summary(store, "e", columns).evaluated == 50 and calls[0] == 3

    # a summary file that does not read back, or one of another key, is computed again
    summary_path(store, "e").write_text("{not json")
    assert stored_summary(store, "e", columns).evaluated == 50 and calls[0] == 4
    summary_path(store, "e").write_text(json.dumps({"key": "0" * 64, "summary": {}}))
    assert stored_summary(store, "e", columns).evaluated == 50 and calls[0] == 5
    assert stored_summary(store, "e", columns).evaluated == 50 and calls[0] == 5


def test_a_summary_that_cannot_be_stored_is_still_given(tmp_path: Path, monkeypatch) -> None:
    make_store(tmp_path, _varied_rows(50))
    store = Store(tmp_path / "store")
    (store.root / "cache").write_text("a file where the folder would go")
    assert stored_summary(store, "e", ["c_int"]) == summarise(connect(store, "e"), ["c_int"])


def test_query_sees_the_views(tiny_run: Path, tmp_path: Path) -> None:
    spec = tiny_run / "spec.toml"
    for sql in ("FROM control_accuracy", "FROM failure_modes(min_count := 2)", "FROM variance_explained",
                "SELECT wilson_high(0, 8) AS high"):
        result = CliRunner().invoke(app, ["query", str(spec), sql])
        assert result.exit_code == 0, result.output
    out = tmp_path / "levels.json"
    result = CliRunner().invoke(app, ["query", str(spec), "FROM control_accuracy", "-o", str(out)])
    assert result.exit_code == 0, result.output
    rows = json.loads(out.read_text())
    assert {"object", "environment", "orientation_yaw", "blur_sigma"} <= {r["parameter"] for r in rows}
    assert sum(r["n"] for r in rows if r["parameter"] == "orientation_yaw") == 8
