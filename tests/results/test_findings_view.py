"""The ``findings`` view over the ``finding_grades`` table: each run's listing, untested until
graded, a listing that comes back keeps its grades, and a run with no finding shows none."""

from __future__ import annotations

from pathlib import Path

from sweep3d.cache import Store, utc_now
from sweep3d.results import FINDINGS_SCHEMA, FINDINGS_TABLE, SOLID, UNTESTED, Finding, grade_row, record_listing
from sweep3d.results.findings import register_findings_view


def _findings(*texts: str) -> list[Finding]:
    return [Finding(f"value x = {t}", "failure mode", f"x = {t}", i, {}, -0.3) for i, t in enumerate(texts)]


def _view(store: Store) -> list[tuple]:
    con = store.connect("e")
    try:
        if not register_findings_view(con, "e"):
            return []
        return con.execute("SELECT text, grade FROM findings ORDER BY rank").fetchall()
    finally:
        con.close()


def test_a_listing_is_untested_until_graded_and_keeps_its_grades_when_it_comes_back(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    a, b = _findings("1", "2"), _findings("3")
    listing = record_listing(store, "e", "m", a, "spec.toml")
    assert _view(store) == [("x = 1", UNTESTED), ("x = 2", UNTESTED)]
    store.append(FINDINGS_TABLE, [grade_row("e", "m", listing, utc_now(), a[0], SOLID, "replicated")], FINDINGS_SCHEMA)
    assert _view(store) == [("x = 1", SOLID), ("x = 2", UNTESTED)]
    before = len(store.readable_segments(FINDINGS_TABLE))
    assert record_listing(store, "e", "m", a, "spec.toml") == listing  # the same findings: nothing written
    assert len(store.readable_segments(FINDINGS_TABLE)) == before and _view(store)[0] == ("x = 1", SOLID)

    record_listing(store, "e", "m", b, "spec.toml")  # the run's findings changed
    assert _view(store) == [("x = 3", UNTESTED)]
    record_listing(store, "e", "m", [], "spec.toml")  # a run that finds nothing shows nothing
    assert _view(store) == []
    record_listing(store, "e", "m", a, "spec.toml")  # the first findings back: their grades with them
    assert _view(store) == [("x = 1", SOLID), ("x = 2", UNTESTED)]


def test_another_experiment_s_listing_is_not_shown(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    record_listing(store, "other", "m", _findings("1"), "spec.toml")
    assert _view(store) == []
