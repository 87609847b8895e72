"""The ``agreement`` view: agreement with its Wilson interval, PPV, NPV and Cohen's κ per source ×
model × object and overall, each checked against a hand computation on a synthetic store, and
right for tiny n (a ratio over nothing, or an undefined κ, is NULL, never NaN)."""

from __future__ import annotations

import math
import tempfile
from datetime import timedelta
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sweep3d.cache.store import Store
from sweep3d.results import connect, wilson_interval
from sweep3d.results.agreement import VERDICT_SCHEMA, VERDICTS
from sweep3d.results.quoting import literal
from tests.helpers import examples
from tests.helpers.realism import LABELS, T1, agreement_rows, hand, job_colours, make_run, sim_verdicts, verdict

MODEL = "realism_model:redblue"

def test_agreement_ppv_npv_kappa_equal_a_hand_computation(tmp_path: Path) -> None:
    make_run(tmp_path)
    sim = sim_verdicts()
    jobs = job_colours()
    photo = {i: (sim[i] if i % 4 else not sim[i]) for i in range(0, len(sim), 2)}  # a quarter flipped
    rows = [verdict(i, c) for i, c in photo.items()]
    rows.append(verdict(1, not sim[1], at=T1 - timedelta(days=1)))  # scored before, then again:
    rows.append(verdict(1, sim[1]))  # the latest verdict counts
    rows.append(verdict(3, True, valid=False))  # an invalid photo verdict is no evidence
    rows.append(verdict(5, True, source="engine:other"))
    Store(tmp_path / "store").append(VERDICTS, rows, VERDICT_SCHEMA)
    photo[1] = sim[1]
    got = {(r["source"], r["object"]): r for r in agreement_rows(tmp_path)}
    for obj in (*LABELS, None):
        pairs = [(sim[i], c) for i, c in sorted(photo.items()) if obj is None or jobs[i]["object"] == obj]
        want, row = hand(pairs), got[("photo", obj)]
        assert row["overall"] == (obj is None) and row["model"] == MODEL
        for key in ("n", "n_agree"):
            assert row[key] == want[key]
        for key in ("agreement", "ppv", "npv", "kappa"):
            assert row[key] == pytest.approx(want[key], abs=1e-12), (obj, key)
        assert (row["wilson_low"], row["wilson_high"]) == pytest.approx(wilson_interval(want["n_agree"], want["n"]))
    one = got[("engine:other", None)]
    assert one["n"] == 1 and one["n_agree"] == int(sim[5])


def test_a_source_that_says_one_thing_everywhere_has_no_kappa(tmp_path: Path) -> None:
    make_run(tmp_path)
    sim = sim_verdicts()
    right = [i for i, c in enumerate(sim) if c][:3]
    Store(tmp_path / "store").append(VERDICTS, [verdict(i, True) for i in right], VERDICT_SCHEMA)
    row = next(r for r in agreement_rows(tmp_path) if r["overall"])
    assert (row["n"], row["agreement"], row["ppv"]) == (3, 1.0, 1.0)
    assert row["npv"] is None and row["kappa"] is None  # nothing wrong in simulation; chance agreement 1
    assert row["wilson_high"] == 1.0 and 0 < row["wilson_low"] < 1


def test_no_verdicts_no_view(tmp_path: Path) -> None:
    make_run(tmp_path)
    con = connect(Store(tmp_path / "store"), "realism")
    assert not con.execute("SELECT count(*) FROM duckdb_views() WHERE view_name = 'agreement'").fetchone()[0]


@settings(max_examples=examples(40), deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.booleans()), min_size=1, max_size=12))
def test_kappa_and_ratios_are_finite_or_null_for_any_small_table(pairs: list[tuple[bool, bool]]) -> None:
    import duckdb

    from sweep3d.results.agreement import register_agreement_views
    from sweep3d.results.views import register_views

    con = duckdb.connect()
    con.execute("CREATE TABLE raw AS SELECT * FROM (VALUES " + ", ".join(
        f"({i}, 'o', 'e', {a}, true, {literal(MODEL)})" for i, (a, _) in enumerate(pairs))
        + ") t(job, object, environment, correct, counted, model)")
    con.execute("CREATE VIEW results_all AS SELECT * FROM raw")
    con.execute("CREATE VIEW results AS SELECT * FROM results_all")
    register_views(con, [])
    with tempfile.TemporaryDirectory() as folder:
        path = Store(folder).append(VERDICTS, [verdict(i, b) for i, (_, b) in enumerate(pairs)], VERDICT_SCHEMA)
        assert register_agreement_views(con, [path], "realism")
        row = con.execute("SELECT n, agreement, ppv, npv, kappa FROM agreement WHERE overall").fetchone()
    want = hand(pairs)
    assert row[0] == want["n"] and row[1] == pytest.approx(want["agreement"])
    for got, key in zip(row[2:], ("ppv", "npv", "kappa")):
        assert (got is None) == (want[key] is None), key
        if got is not None:
            assert math.isfinite(got) and got == pytest.approx(want[key], abs=1e-12)


def test_sweep3d_query_reads_the_agreement_view(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from sweep3d.cli import app

    spec = make_run(tmp_path)
    Store(tmp_path / "store").append(VERDICTS, [verdict(0, True), verdict(1, False)], VERDICT_SCHEMA)
    result = CliRunner().invoke(app, ["query", str(spec), "SELECT source, n FROM agreement WHERE overall",
                                      "--format", "csv"])
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines() == ["source,n", "photo,2"]  # the locked-down connection reads verdicts
