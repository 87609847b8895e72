"""Margins and fragile verdicts: the margin read from stored predictions against the exact one,
the stability views' threshold rule, ``drop_fragile``, the check's sample and its changes."""

from __future__ import annotations

from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import duckdb
import numpy as np
import pyarrow as pa
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sweep3d.cache.store import Store
from sweep3d.followups.stability.changes import changed, level_noise, margins, toggled_dither
from sweep3d.followups.stability.check import SCHEMA, stability_key, stratified_sample
from sweep3d.results import connect, summarise
from sweep3d.results.fragile import MARGIN_EDGES, create_margin_macro
from sweep3d.spec.columns import DROP_FRAGILE_METADATA
from sweep3d.stages.infer.evaluators.classification import ranked_rows
from sweep3d.stages.infer.evaluators.evaluator import Truth
from sweep3d.stages.infer.labels import LabelMap
from tests.helpers import examples

T0 = datetime(2024, 1, 1, tzinfo=timezone.utc)


def _sql_margin(con: duckdb.DuckDBPyConnection, row: dict[str, Any]) -> float | None:
    return con.execute("SELECT class_margin(?::INTEGER[], ?::FLOAT[], ?::INTEGER[], ?::DOUBLE)",
                       [row["topk"], row["topk_probs"], row["label_ids"], row["label_prob"]]).fetchone()[0]


def _determined(row: dict[str, Any], top_k: int, classes: int) -> bool:
    """Whether the stored top-k fixes the margin exactly (else the macro gives a bound nearer 0)."""
    ids, topk = set(row["label_ids"]), row["topk"]
    if row["correct"]:
        return any(i not in ids for i in topk) or len(ids) == classes
    return any(i in ids for i in topk) or len(ids) == 1


logit_rows = st.integers(1, 7).flatmap(lambda c: st.tuples(
    # small integers make exact ties; huge ones make probabilities of exactly 0 and 1
    st.lists(st.one_of(st.integers(-3, 3).map(float), st.sampled_from([-800.0, 800.0]),
                       st.floats(-20, 20, allow_nan=False)), min_size=c, max_size=c),
    st.sets(st.integers(0, c - 1), min_size=1, max_size=c),
    st.integers(1, 5)))


@settings(max_examples=examples(150), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(logit_rows)
def test_stored_margin_is_the_exact_margin_or_a_bound_nearer_zero(case) -> None:
    logits, ids, top_k = case
    classes = len(logits)
    labels = LabelMap([[f"c{i}"] for i in range(classes)])
    row = ranked_rows(np.array([logits]), [Truth(tuple(sorted(ids)))], labels, top_k)[0]
    exact = float(margins(np.array([logits]), [sorted(ids)])[0])
    con = duckdb.connect()
    create_margin_macro(con)
    got = _sql_margin(con, row)
    assert got is not None and np.isfinite(got) and -1.0 <= got <= 1.0
    if _determined(row, top_k, classes):
        assert got == pytest.approx(exact, abs=2e-7)
    else:  # between 0 and the exact margin: never surer than it is
        assert min(0.0, exact) - 2e-7 <= got <= max(0.0, exact) + 2e-7
    # the sign is the verdict's (a tie, 0, may go either way)
    assert (got > 0 and row["correct"]) or (got < 0 and not row["correct"]) or abs(got) <= 2e-7


def test_margin_edges_one_class_certainty_and_ties() -> None:
    con = duckdb.connect()
    create_margin_macro(con)
    one = LabelMap([["only"]])
    row = ranked_rows(np.array([[3.0]]), [Truth((0,))], one, 5)[0]
    assert _sql_margin(con, row) == 1.0  # one class: nothing else to prefer
    two = LabelMap([["a"], ["b"]])
    sure = ranked_rows(np.array([[0.0, 900.0]]), [Truth((0,))], two, 5)[0]
    assert _sql_margin(con, sure) == -1.0  # p = 0 against p = 1
    tie = ranked_rows(np.array([[1.0, 1.0]]), [Truth((1,))], two, 5)[0]
    assert _sql_margin(con, tie) == 0.0 and margins(np.array([[1.0, 1.0]]), [(1,)])[0] == 0.0
    invalid = {"topk": None, "topk_probs": None, "label_ids": None, "label_prob": None}
    assert _sql_margin(con, invalid) is None  # an invalid prediction has no margin, never NaN
    assert np.isnan(margins(np.array([[np.nan, 1.0]]), [(0,)])[0])  # flagged by the check, not stored


# -- the stability views over a synthetic store ------------------------------------------------


def _prediction(key: str, probs: list[float], correct: bool) -> dict[str, Any]:
    """A classification row of a two-class model whose true class is 0."""
    order = [0, 1] if correct else [1, 0]
    top = sorted(probs, reverse=True)
    return {"pred_key": key, "image_key": key, "created_at": T0, "valid": True, "correct": correct,
            "top1": order[0], "top1_label": f"c{order[0]}", "topk": order, "topk_labels": [f"c{i}" for i in order],
            "topk_probs": top, "label_prob": top[0] if correct else top[1], "loss": 1.0, "label_ids": [0]}


def _store(folder: Path, margins_: list[float], drop: bool = False) -> Store:
    """One job per margin (a two-class model: p(true) = (1 + margin) / 2)."""
    store = Store(folder / "store")
    jobs, predictions = [], []
    for i, m in enumerate(margins_):
        key = f"k{i}"
        jobs.append({"experiment": "e", "job": i, "object": "obj", "environment": "env", "c_a": i % 3,
                     "render_key": key, "image_key": key, "pred_key": key})
        p = (1 + m) / 2
        predictions.append(_prediction(key, [p, 1 - p], m > 0))
    table = pa.Table.from_pylist(jobs)
    if drop:
        table = table.replace_schema_metadata({DROP_FRAGILE_METADATA: b"true"})
    store.write_table_file(store.jobs_path("e"), table)
    store.append("predictions", predictions)
    return store


def _checked(store: Store, flips: dict[str, tuple[float, bool]]) -> None:
    rows = [{"stability_key": stability_key(key, "noise", 0), "pred_key": key, "image_key": key, "change": "noise",
             "seed": 0, "base_correct": m > 0, "base_margin": m, "correct": (m > 0) != flipped, "margin": -m if flipped else m,
             "flipped": flipped, "created_at": T0} for key, (m, flipped) in flips.items()]
    store.append("stability", rows, SCHEMA)


MARGINS = [-0.6, -0.3, -0.04, -0.015, -0.005, 0.003, 0.012, 0.03, 0.08, 0.4, 0.7]


def test_fragile_is_unknown_before_a_check_and_run_says_nothing(tmp_path: Path) -> None:
    store = _store(tmp_path, MARGINS)
    con = connect(store, "e")
    got = con.execute("SELECT margin, fragile FROM results ORDER BY job").fetchall()
    assert [m for m, _ in got] == pytest.approx(MARGINS, abs=1e-6)
    assert all(f is None for _, f in got)  # unknown, never false
    summary = summarise(con, ["c_a"])
    assert summary.fragile_failures is None and summary.fragile_threshold is None


def test_threshold_is_the_top_of_the_highest_bin_that_flipped(tmp_path: Path) -> None:
    store = _store(tmp_path, MARGINS)
    # a flip at 0.012 (bin [0.01, 0.02)), none at 0.003, 0.03 or 0.4: the threshold is 0.02, although
    # the bin below did not flip (conservative: a bin without a flip below one that flipped says nothing)
    _checked(store, {"k5": (0.003, False), "k6": (0.012, True), "k7": (0.03, False), "k9": (0.4, False)})
    con = connect(store, "e")
    assert con.execute("SELECT threshold, checked, flipped FROM fragile_threshold").fetchone() == (0.02, 4, 1)
    bins = {r[0]: r[1:] for r in con.execute("SELECT bin, n, flips, flip_rate, wilson_low, wilson_high "
                                             "FROM stability_bins").fetchall()}
    assert len(bins) == len(MARGIN_EDGES)
    assert bins[1][:3] == (1, 1, 1.0) and bins[0][:3] == (1, 0, 0.0)
    assert bins[1][3] == pytest.approx(0.2065, abs=1e-3) and bins[1][4] == 1.0  # Wilson, 1 of 1
    assert bins[4][:2] == (0, 0) and bins[4][2] is None  # no image: no rate, not 0
    fragile = dict(con.execute("SELECT job, fragile FROM results").fetchall())
    assert [fragile[i] for i in range(len(MARGINS))] == [abs(m) < 0.02 for m in MARGINS]
    summary = summarise(con, ["c_a"])
    assert (summary.fragile_failures, summary.fragile_threshold, summary.fragile_checked) == (2, 0.02, 4)
    assert summary.wrong == 5 and summary.fragile_dropped == 0


def test_an_image_that_flipped_is_fragile_even_above_the_threshold_rule(tmp_path: Path) -> None:
    store = _store(tmp_path, MARGINS)
    # its base margin (re-inferred) put it in a low bin, its stored one is higher: still fragile
    _checked(store, {"k8": (0.009, True)})
    con = connect(store, "e")
    assert con.execute("SELECT threshold FROM fragile_threshold").fetchone()[0] == 0.01
    assert con.execute("SELECT fragile FROM results WHERE job = 8").fetchone()[0] is True
    assert con.execute("SELECT fragile FROM results WHERE job = 5").fetchone()[0] is True  # 0.003 < 0.01
    assert con.execute("SELECT fragile FROM results WHERE job = 6").fetchone()[0] is False


def test_a_bin_sets_the_threshold_only_when_one_in_ten_flips_beyond_doubt(tmp_path: Path) -> None:
    margins = [0.3 + i / 100 for i in range(20)] + [-0.6, 0.005]  # 20 in bin [0.2, 0.5), then two more
    store = _store(tmp_path, margins)
    # 1 of 20 flipped in [0.2, 0.5) (5 %): no threshold from it, but that image is fragile
    _checked(store, {f"k{i}": (margins[i], i == 3) for i in range(20)})
    con = connect(store, "e")
    assert con.execute("SELECT threshold, checked, flipped FROM fragile_threshold").fetchone() == (0.0, 20, 1)
    fragile = dict(con.execute("SELECT job, fragile FROM results").fetchall())
    assert [j for j, f in fragile.items() if f] == [3]
    store = _store(tmp_path / "two", margins)  # 2 of 20 (10 %, Wilson's lower bound 2.8 %): not beyond doubt
    _checked(store, {f"k{i}": (margins[i], i in (3, 4)) for i in range(20)})
    assert connect(store, "e").execute("SELECT threshold FROM fragile_threshold").fetchone()[0] == 0.0
    store = _store(tmp_path / "six", margins)  # 6 of 20 (30 %, lower bound 14.5 %): the bin's margins are fragile
    _checked(store, {f"k{i}": (margins[i], i < 6) for i in range(20)})
    con = connect(store, "e")
    assert con.execute("SELECT threshold FROM fragile_threshold").fetchone()[0] == 0.5
    fragile = dict(con.execute("SELECT job, fragile FROM results").fetchall())
    assert sorted(j for j, f in fragile.items() if f) == [*range(20), 21]  # -0.6 is not


def test_a_later_check_replaces_an_image_s_rows_instead_of_adding_chances_to_flip(tmp_path: Path) -> None:
    store = _store(tmp_path, MARGINS)
    _checked(store, {"k6": (0.012, True)})  # seed 0: flipped
    later = [{"stability_key": stability_key("k6", "noise", 1), "pred_key": "k6", "image_key": "k6",
              "change": "noise", "seed": 1, "base_correct": True, "base_margin": 0.012, "correct": True,
              "margin": 0.012, "flipped": False, "created_at": T0 + timedelta(seconds=1)}]
    store.append("stability", later, SCHEMA)  # seed 1, checked later: not flipped
    con = connect(store, "e")
    assert con.execute("SELECT checked, flipped FROM fragile_threshold").fetchone() == (1, 0)


def test_no_flip_makes_nothing_fragile_but_the_check_is_known(tmp_path: Path) -> None:
    store = _store(tmp_path, MARGINS)
    _checked(store, {"k4": (-0.005, False), "k5": (0.003, False)})
    con = connect(store, "e")
    assert con.execute("SELECT threshold FROM fragile_threshold").fetchone()[0] == 0.0
    assert {f for (f,) in con.execute("SELECT fragile FROM results").fetchall()} == {False}
    assert summarise(con, ["c_a"]).fragile_failures == 0


def test_drop_fragile_leaves_them_out_of_what_is_counted(tmp_path: Path) -> None:
    store = _store(tmp_path, MARGINS, drop=True)
    _checked(store, {"k6": (0.012, True)})
    con = connect(store, "e")
    summary = summarise(con, ["c_a"])
    fragile = sum(abs(m) < 0.02 for m in MARGINS)
    assert summary.counted == len(MARGINS) - fragile and summary.fragile_dropped == fragile
    assert summary.fragile_failures == 2 and summary.wrong == 5 - 2
    assert con.execute("SELECT count(*) FROM control_levels WHERE counted AND parameter = 'c_a'").fetchone()[0] \
        == len(MARGINS) - fragile
    plain = connect(_store(tmp_path / "plain", MARGINS), "e")
    assert summarise(plain, ["c_a"]).counted == len(MARGINS)  # without the key, nothing is left out


def test_the_stability_table_is_a_store_table(tmp_path: Path) -> None:
    from sweep3d.cache.maintenance import verify

    store = _store(tmp_path, MARGINS)
    _checked(store, {"k6": (0.012, True)})
    _checked(store, {"k6": (0.012, True)})  # written twice: one row per key in the view
    con = connect(store, "e")
    assert con.execute("SELECT count(*) FROM stability").fetchone()[0] == 1
    assert verify(store.root).ok


# -- the check's sample and changes -------------------------------------------------------------


def test_sample_takes_bins_in_turn_near_ties_first_and_is_seeded() -> None:
    rows = [(f"a{i}", 0.001 * i) for i in range(3)] + [(f"b{i}", 0.3 + 0.001 * i) for i in range(50)]
    picked = stratified_sample(rows, 8, seed=1)
    assert {k for k in picked if k.startswith("a")} == {"a0", "a1", "a2"}  # every near-tie
    assert len(picked) == len(set(picked)) == 8
    assert picked == stratified_sample(rows, 8, seed=1) and picked != stratified_sample(rows, 8, seed=2)
    assert stratified_sample(rows, 100, seed=0).__len__() == len(rows)


def test_changes_are_one_level_seeded_and_about_their_stated_share() -> None:
    rng = np.random.default_rng(0)
    pixels = rng.integers(1, 255, size=(64, 64, 3), dtype=np.uint8)
    noisy = level_noise(pixels, np.random.default_rng(1))
    moved = np.any(noisy != pixels, axis=2)
    assert 0.07 < moved.mean() < 0.13 and np.abs(noisy.astype(int) - pixels).max() == 1
    dithered = toggled_dither(pixels, np.random.default_rng(1))
    assert 0.2 < (dithered != pixels).mean() < 0.3 and np.abs(dithered.astype(int) - pixels).max() == 1
    assert np.array_equal(changed(pixels, "noise", 3, "key"), changed(pixels, "noise", 3, "key"))
    assert not np.array_equal(changed(pixels, "noise", 3, "key"), changed(pixels, "noise", 4, "key"))
    assert changed(pixels, "resize", 3, "key") is pixels  # the model's arithmetic changes, not the pixels
    edge = np.zeros((8, 8, 3), np.uint8)
    assert level_noise(edge, np.random.default_rng(0)).max() <= 1  # clipped at 0, never wrapped to 255
    assert stability_key("p", "resize", 0) == stability_key("p", "resize", 9)
    assert stability_key("p", "noise", 0) != stability_key("p", "noise", 9)
