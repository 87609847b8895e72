"""``sweep3d explain``'s rows are the store's ``counterfactuals`` table: each explain makes them the
experiment's rows (a newer row of each failure it searched, the others dropped, the same rows
not written again), the views show the experiment's own, ``cache verify``, ``compact`` and
``stats`` see the table, and a store's older ``explain/<experiment>.parquet`` is read while the
table holds none of the experiment's rows. No render or search: the rows are written here."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from sweep3d.cache import Store, compact_table, contract_of, store_stats, verify
from sweep3d.followups.explain import counterfactual_key, write_counterfactuals
from sweep3d.results import COUNTERFACTUALS, SCHEMA, legacy_counterfactuals_path
from sweep3d.results.counterfactuals import register_counterfactual_views


def row(experiment: str, job: int, distance: float = 0.5, **more) -> dict:
    """One failure searched: its job, its prediction's key and a found fix at ``distance``."""
    out = {name: None for name in SCHEMA.names}
    out.update(experiment=experiment, failure_job=job, failure_pred_key=f"pred-{job}", found=True, complete=True,
               parameters=["blur_sigma"], shares=[distance], n_changed=1, distance=distance, **more)
    return out


def shown(store: Store, experiment: str) -> list[tuple[int, float]] | None:
    """(failure_job, distance) of the ``counterfactuals`` view for ``experiment``; None: no view."""
    files = store.view_files(experiment)
    con = store.connect(experiment, files)
    try:
        register_counterfactual_views(con, store, experiment, files.get(COUNTERFACTUALS, []))
        if not con.execute(f"SELECT count(*) FROM duckdb_views() WHERE view_name = '{COUNTERFACTUALS}'").fetchone()[0]:
            return None
        return con.execute("SELECT failure_job, distance FROM counterfactuals").fetchall()
    finally:
        con.close()


def test_each_explain_makes_its_rows_the_experiment_s(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    assert write_counterfactuals(store, "e", [row("e", 1), row("e", 2), row("e", 3)])
    assert write_counterfactuals(store, "other", [row("other", 1, 0.9)])
    assert shown(store, "e") == [(1, 0.5), (2, 0.5), (3, 0.5)]

    segments = store.segments(COUNTERFACTUALS)
    assert not write_counterfactuals(store, "e", [row("e", 1), row("e", 2), row("e", 3)])  # the same found again
    assert store.segments(COUNTERFACTUALS) == segments

    assert write_counterfactuals(store, "e", [row("e", 2, 0.25), row("e", 4)])  # a smaller budget, another sample
    assert shown(store, "e") == [(2, 0.25), (4, 0.5)]  # the latest explain's rows only: a panel counts them
    assert shown(store, "other") == [(1, 0.9)]  # another experiment's are its own
    assert shown(store, "never") is None  # never explained: no view, as before
    assert write_counterfactuals(store, "e", []) and shown(store, "e") is None  # no failures left to search


def test_the_table_is_the_store_s_like_any_other(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    write_counterfactuals(store, "e", [row("e", 1), row("e", 2)])
    write_counterfactuals(store, "e", [row("e", 1, 0.1), row("e", 2)])  # job 1 nearer: a newer row of its key
    stats = next(s for s in store_stats(store.root) if s.name == COUNTERFACTUALS)
    assert (stats.files, stats.rows, stats.keys) == (2, 3, 2)
    assert verify(store.root).ok
    with store.lock():
        done = compact_table(store, COUNTERFACTUALS)
    assert done is not None and (done.rows_before, done.rows_after) == (3, 2)
    assert shown(store, "e") == [(1, 0.1), (2, 0.5)]
    contract = contract_of(COUNTERFACTUALS)
    assert (contract.key, contract.merge) == ("counterfactual_key", "newest")
    assert counterfactual_key("e", "p") != counterfactual_key("f", "p")


def test_an_older_file_is_read_until_the_next_explain_replaces_it(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    path = legacy_counterfactuals_path(store, "e")
    path.parent.mkdir(parents=True)
    older = pa.schema(list(SCHEMA)[:SCHEMA.get_field_index("fix_fragile")])  # before the trust columns
    pq.write_table(pa.Table.from_pylist([{k: row("e", 7)[k] for k in older.names}], schema=older), path)
    write_counterfactuals(store, "other", [row("other", 1)])
    assert shown(store, "e") == [(7, 0.5)]  # the table holds none of e's rows: the file, as before
    assert path.exists()  # a reader changes nothing

    write_counterfactuals(store, "e", [row("e", 8)])
    assert not path.exists() and shown(store, "e") == [(8, 0.5)]
