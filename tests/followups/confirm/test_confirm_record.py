"""``sweep3d confirm``'s verdicts are rows of the store's ``confirmations`` table: read back as the
callers read them (claim key → entry), a later confirmation replacing the claims it tests and
keeping the others, seen by ``query``'s views, ``cache compact``, ``stats`` and ``verify``; a
store's older ``cache/confirm/<experiment>.json`` is read as a fallback and moved into the table
by the next write. No render: the verdicts are written here."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from datetime import datetime, timedelta, timezone
from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from sweep3d.cache import Store, compact_table, contract_of, store_stats, verify
from sweep3d.followups.confirm import CONFIRMATIONS, confirmation_key, mark, read_verdicts, status, write_verdicts
from sweep3d.followups.confirm.record import legacy_path
from sweep3d.followups.confirm.stored import SCHEMA, VERDICT_FIELDS
from sweep3d.results import CONFIRMED, UNCONFIRMED, Verdict


def verdict(status: str = CONFIRMED, pairs: int = 20, difference: float = -0.42, **more) -> Verdict:
    return Verdict(status, pairs, 6, 11, 1, 2, 0.35, 0.85, difference, difference - 0.2, difference + 0.2, 0.001,
                   0.002, 2, **more)


def entry(v: Verdict, text: str = "blur = high", **more) -> dict:
    """What ``confirm`` records of one claim."""
    return {"text": text, "verdict": v.as_dict(), "renders": 40, "seed": 3, "drawn": v.pairs,
            "experiment": "e-confirm", **more}


def test_the_entries_read_back_as_written_and_a_later_confirmation_replaces_only_what_it_tests(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    first = {"region blur = high": entry(verdict()), "region yaw = 90": entry(verdict(UNCONFIRMED, 0), "yaw = 90")}
    write_verdicts(store, "e", first)
    write_verdicts(store, "other", {"region blur = high": entry(verdict(pairs=4), experiment="other-confirm")})
    assert read_verdicts(store, "e") == first  # the return shape the callers read, exactly

    again = entry(verdict("not replicated", 30, -0.01))
    write_verdicts(store, "e", {"region blur = high": again})
    verdicts = read_verdicts(store, "e")
    assert verdicts == {**first, "region blur = high": again}  # the claim it tested, replaced; the other kept
    assert status(verdicts, "region blur = high") == "not replicated" and status(verdicts, "nothing") == UNCONFIRMED
    assert mark(verdicts, "region yaw = 90") == " [unconfirmed: no fresh configuration could be drawn]"
    assert read_verdicts(store, "other")["region blur = high"]["verdict"]["pairs"] == 4  # each experiment its own
    assert read_verdicts(store, "nobody") == {}


def test_the_table_is_the_store_s_like_any_other(tmp_path: Path) -> None:
    """Its views (the newest row of a claim), compaction (keeps that row), stats and verify."""
    store = Store(tmp_path / "store")
    write_verdicts(store, "e", {"a": entry(verdict()), "b": entry(verdict())})
    write_verdicts(store, "e", {"a": entry(verdict("inconclusive", 64))})
    con = store.connect()
    try:
        rows = con.execute(f"SELECT claim, status, pairs FROM {CONFIRMATIONS} ORDER BY claim").fetchall()
    finally:
        con.close()
    assert rows == [("a", "inconclusive", 64), ("b", CONFIRMED, 20)]
    stats = next(s for s in store_stats(store.root) if s.name == CONFIRMATIONS)
    assert (stats.files, stats.rows, stats.keys) == (2, 3, 2)
    with store.lock():
        done = compact_table(store, CONFIRMATIONS)
    assert done is not None and (done.rows_before, done.rows_after) == (3, 2)
    assert read_verdicts(store, "e")["a"]["verdict"]["status"] == "inconclusive"
    assert verify(store.root).ok


def test_the_contract_names_every_field_of_a_verdict() -> None:
    """A field added to :class:`Verdict` needs a column, or ``run`` would read it back as missing."""
    assert [f.name for f in dataclasses.fields(Verdict)] == VERDICT_FIELDS.names
    contract = contract_of(CONFIRMATIONS)
    assert (contract.key, contract.merge) == ("confirmation_key", "newest")
    assert set(contract.columns) == set(SCHEMA.names)
    assert confirmation_key("e", "a") != confirmation_key("e-", "a") != confirmation_key("e", "a ")


def legacy(store: Store, experiment: str, claims: dict, age: float = 3600.0) -> Path:
    """A store's JSON file from before the table, written ``age`` seconds ago."""
    path = legacy_path(store, experiment)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"format": 1, "claims": claims}))
    then = datetime.now(timezone.utc).timestamp() - age
    os.utime(path, (then, then))
    return path


def test_an_older_json_file_is_read_as_a_fallback_and_moved_in_by_the_next_write(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    old = verdict().as_dict()
    del old["futility"]  # a verdict from before the field: read as it was, moved in as NULL
    earlier = {"old": {"text": "blur = high", "verdict": old, "renders": 16, "seed": 0, "drawn": 8,
                       "experiment": "e-confirm"},
               "both": entry(verdict(pairs=2))}
    path = legacy(store, "e", earlier)
    assert read_verdicts(store, "e") == earlier  # nothing in the table yet: the file, as before
    assert path.exists() and store.segments(CONFIRMATIONS) == []  # a reader changes nothing

    write_verdicts(store, "e", {"both": entry(verdict(pairs=30)), "new": entry(verdict())})
    assert not path.exists()
    verdicts = read_verdicts(store, "e")
    assert set(verdicts) == {"old", "both", "new"} and verdicts["both"]["verdict"]["pairs"] == 30
    assert verdicts["old"]["verdict"] == {**old, "futility": None} and verdicts["old"]["renders"] == 16
    [moved] = [r for r in store.table(CONFIRMATIONS).to_pylist() if r["claim"] == "old"]
    assert moved["created_at"] < datetime.now(timezone.utc) - timedelta(minutes=30)  # dated as the file


def test_a_json_file_with_a_value_no_column_holds_is_kept_and_still_read(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    odd = {"text": "t", "verdict": {**verdict().as_dict(), "pairs": "twenty"}}
    path = legacy(store, "e", {"odd": odd})
    write_verdicts(store, "e", {"new": entry(verdict())})
    assert path.exists() and read_verdicts(store, "e")["odd"] == odd and "new" in read_verdicts(store, "e")


finite = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=25, deadline=None)
@given(difference=finite, p=st.floats(0.0, 1.0), pairs=st.integers(0, 2**62))
def test_a_verdict_s_numbers_read_back_exactly(tmp_path_factory, difference: float, p: float, pairs: int) -> None:
    store = Store(tmp_path_factory.mktemp("edges") / "store")
    v = dataclasses.replace(verdict(), difference=difference, difference_low=difference,
                            p_value=p, p_holm=p, pairs=pairs)
    write_verdicts(store, "e", {"k": entry(v)})
    back = read_verdicts(store, "e")["k"]["verdict"]
    assert back == v.as_dict() and math.copysign(1, back["difference"]) == math.copysign(1, difference)
