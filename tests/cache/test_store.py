"""The content-addressed store: Parquet segments, DuckDB views, atomic writes, the writer lock."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path

import duckdb
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store, atomic_write
from sweep3d.cli import app
from sweep3d.core.errors import StoreBusyError, UserError
from sweep3d.results import connect as connect_results
from tests.helpers import FixedUuid, one_line, store_tree

T0 = datetime(2024, 1, 1, tzinfo=timezone.utc)


def render_row(key: str, seconds: float = 1.0, minutes: int = 0) -> dict:
    return {"render_key": key, "width": 32, "height": 32, "valid": True, "seconds": seconds,
            "created_at": T0 + timedelta(minutes=minutes)}


def files_under(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


# -- segments and views ----------------------------------------------------------------------


def test_append_and_keys_round_trip(tmp_path):
    store = Store(tmp_path / "store")
    assert store.keys("renders") == set()
    assert store.append("renders", []) is None

    first = store.append("renders", [render_row("a"), render_row("b")])
    second = store.append("renders", [render_row("c")])

    assert first is not None and second is not None and first != second
    assert store.segments("renders") == sorted([first, second])
    assert store.keys("renders") == {"a", "b", "c"}
    assert store.keys("predictions") == set()
    assert pq.read_table(first).num_rows == 2


def test_views_deduplicate_keys_keeping_the_first_row(tmp_path):
    store = Store(tmp_path / "store")
    store.append("renders", [render_row("a", seconds=1.0, minutes=0), render_row("b", minutes=1)])
    store.append("renders", [render_row("a", seconds=9.0, minutes=5), render_row("c", minutes=2)])

    con = store.connect()
    assert con.execute("select count(*) from renders").fetchone()[0] == 3
    assert con.execute("select seconds from renders where render_key = 'a'").fetchone()[0] == 1.0
    raw = duckdb.connect().execute(
        f"select count(*) from read_parquet('{store.table_dir('renders')}/*.parquet')"
    ).fetchone()[0]
    assert raw == 4  # both copies are on disk; only the view dedupes


def test_results_view_joins_jobs_and_predictions(tmp_path):
    import pyarrow as pa

    store = Store(tmp_path / "store")
    jobs = pa.Table.from_pylist([
        {"experiment": "e", "job": i, "render_key": f"r{i}", "image_key": f"i{i}", "pred_key": f"p{i}"}
        for i in range(3)
    ])
    store.write_table_file(store.jobs_path("e"), jobs)
    store.append("predictions", [
        {"pred_key": "p0", "image_key": "i0", "correct": True, "created_at": T0},
        {"pred_key": "p2", "image_key": "i2", "correct": False, "created_at": T0},
        {"pred_key": "p0", "image_key": "i0", "correct": False, "created_at": T0 + timedelta(1)},
    ])
    con = connect_results(store, "e")
    rows = con.execute("select job, correct from results order by job").fetchall()
    assert rows == [(0, True), (2, False)]
    assert "results" not in {r[0] for r in store.connect().execute("show tables").fetchall()}


def test_half_written_files_are_ignored(tmp_path):
    store = Store(tmp_path / "store")
    store.append("renders", [render_row("a")])
    table = store.table_dir("renders")
    (table / ".00000000000000000001-1-deadbeef.parquet.0123abcd.tmp").write_bytes(b"PAR1 half a footer")
    (table / ".hidden.parquet").write_bytes(b"not parquet at all")

    assert store.keys("renders") == {"a"}
    assert len(store.segments("renders")) == 1
    assert store.connect().execute("select count(*) from renders").fetchone()[0] == 1


def test_atomic_write_leaves_only_the_target(tmp_path):
    target = tmp_path / "blobs" / "ab" / "abcdef.png"
    atomic_write(target, b"first")
    atomic_write(target, b"second")
    assert target.read_bytes() == b"second"
    assert files_under(tmp_path) == ["blobs/ab/abcdef.png"]


def test_table_files_are_written_atomically(tmp_path):
    store = Store(tmp_path / "store")
    for i in range(3):
        store.append("images", [{"image_key": f"k{i}", "created_at": T0}])
    leftovers = [p for p in (tmp_path / "store").rglob("*") if p.name.endswith(".tmp")]
    assert leftovers == []
    assert store.keys("images") == {"k0", "k1", "k2"}


def test_segment_writer_flushes_on_exit(tmp_path):
    store = Store(tmp_path / "store")
    with store.segment_writer("renders", every=3600.0) as writer:
        for key in "abc":
            writer.add(render_row(key))
        assert store.keys("renders") == set()  # still buffered
    assert store.keys("renders") == {"a", "b", "c"}
    assert writer.written == 3


def test_blob_paths_shard_by_key_prefix(tmp_path):
    store = Store(tmp_path)
    assert store.blob_path("abcdef") == tmp_path / "blobs" / "ab" / "abcdef.png"
    assert store.jobs_path("quickstart").name == "quickstart.parquet"  # safe names keep their paths


def test_experiment_names_never_share_a_jobs_file(tmp_path):
    """``a/b`` and ``a_b`` once both wrote jobs/a_b.parquet; a name is its own file name only when safe."""
    store = Store(tmp_path)
    names = ["a/b", "a_b", "a b", "a\\b", "a_b~", "A_b", "x" * 200, "x" * 199 + "y", "é/1", "é_1", ".", ".."]
    paths = {store.jobs_path(name) for name in names}
    assert len(paths) == len(names)
    assert all(p.parent == tmp_path / "jobs" and len(p.name.encode()) < 160 for p in paths)
    assert store.jobs_path("my-exp_1.0").name == "my-exp_1.0.parquet"
    assert store.jobs_path("my exp/1").name.startswith("my_exp_1~")
    assert store.jobs_path("a/b") == store.jobs_path("a/b")  # and the same name always the same file
    assert len({store.report_path(name) for name in names}) == len(names)


# -- the writer lock -------------------------------------------------------------------------

HOLDER = """
import sys, time
from sweep3d.cache.store import Store

with Store(sys.argv[1]).lock():
    print("locked", flush=True)
    if sys.argv[2] == "stdin":
        sys.stdin.readline()
    else:
        time.sleep(float(sys.argv[2]))
"""


def hold_lock(root: Path, until: str) -> subprocess.Popen:
    """Start a process that holds ``root``'s lock until a line on stdin or for ``until`` seconds."""
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(root), until],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    assert line.strip() == "locked", line
    return proc


def test_second_writer_gets_a_clear_busy_error(tmp_path):
    root = tmp_path / "store"
    proc = hold_lock(root, "stdin")
    try:
        with pytest.raises(StoreBusyError) as caught:
            with Store(root).lock():
                pass
        message = str(caught.value)
        assert str(root) in message
        assert f"pid {proc.pid}" in message
        assert "--wait" in message
        assert isinstance(caught.value, UserError)
    finally:
        proc.stdin.write("\n")
        proc.stdin.close()
        proc.wait(timeout=30)
    with Store(root).lock():  # released with the process
        pass


def test_two_threads_of_one_process_are_told_the_store_is_in_use(tmp_path):
    """Two ``Experiment`` objects run in two threads: the second was told the store "is not
    writable (No such file or directory)", the two threads' writability probes having one name,
    each removing the other's (issue 45, item 8)."""
    import threading

    root = tmp_path / "store"
    threads, start, errors = 8, threading.Barrier(8), []

    def probe() -> None:
        start.wait()
        for _ in range(200):
            try:
                Store(root).ensure_writable()
            except UserError as exc:
                errors.append(str(exc))

    workers = [threading.Thread(target=probe) for _ in range(threads)]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join()
    assert errors == [] and not list(root.glob(".probe-*"))

    held, release, outcome = threading.Event(), threading.Event(), []

    def first() -> None:
        with Store(root).lock():
            held.set()
            release.wait(30)

    holder = threading.Thread(target=first)
    holder.start()
    try:
        assert held.wait(30)
        with pytest.raises(StoreBusyError, match=rf"^store {root} is in use by sweep3d pid {os.getpid()}"):
            with Store(root).lock():
                outcome.append("entered")
    finally:
        release.set()
        holder.join()
    assert outcome == []


def test_wait_lets_the_second_writer_in_after_release(tmp_path):
    root = tmp_path / "store"
    proc = hold_lock(root, "1.5")
    try:
        start = time.monotonic()
        with pytest.raises(StoreBusyError):
            with Store(root).lock(wait=0.3):
                pass
        with Store(root).lock(wait=30.0):
            waited = time.monotonic() - start
        assert 1.0 <= waited < 25.0  # it waited for the holder's 1.5 s, then got in
    finally:
        proc.wait(timeout=30)


def test_lock_is_reentrant_across_sequential_uses(tmp_path):
    store = Store(tmp_path / "store")
    for _ in range(2):
        with store.lock():
            assert (tmp_path / "store" / "lock").read_text().startswith("sweep3d pid")


def test_store_under_a_file_is_a_user_error(tmp_path):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")
    with pytest.raises(UserError, match="not writable.*experiment.store"):
        with Store(blocker / "store").lock():
            pass


def test_read_only_store_is_a_user_error(tmp_path):
    parent = tmp_path / "ro"
    parent.mkdir()
    parent.chmod(0o500)
    try:
        if os.access(parent, os.W_OK):
            pytest.skip("running with privileges that ignore folder permissions")
        with pytest.raises(UserError, match="not writable"):
            Store(parent / "store").ensure_writable()
    finally:
        parent.chmod(0o700)


# -- a real run's store ----------------------------------------------------------------------


def test_real_run_tables_open_with_plain_duckdb(tiny_run):
    store = tiny_run / "store"
    con = duckdb.connect()
    jobs = con.execute(
        f"select count(*), count(distinct pred_key), count(distinct render_key) "
        f"from read_parquet('{store}/jobs/tiny.parquet')"
    ).fetchone()
    predictions = con.execute(
        f"select count(distinct pred_key) from read_parquet('{store}/tables/predictions/*.parquet')"
    ).fetchone()[0]
    renders = con.execute(
        f"select count(distinct render_key) from read_parquet('{store}/tables/renders/*.parquet')"
    ).fetchone()[0]
    assert jobs[0] > 0
    assert predictions == jobs[1]
    assert renders == jobs[2]
    for (key,) in con.execute(f"select render_key from read_parquet('{store}/tables/renders/*.parquet')").fetchall():
        assert Store(store).blob_path(key).is_file()


def _results_count(folder: Path) -> int:
    from tests.helpers import load_spec

    loaded = load_spec(folder / "spec.toml")
    return connect_results(Store(loaded.store), loaded.name).execute("select count(*) from results").fetchone()[0]


def test_query_prints_a_table(tiny_run):
    result = CliRunner().invoke(
        app, ["query", str(tiny_run / "spec.toml"),
              "select environment, count(*) as n from results group by environment order by environment"]
    )
    assert result.exit_code == 0, result.output
    assert "environment" in result.output
    assert "studio" in result.output and "white" in result.output


def test_query_limit_says_more_rows_exist(tiny_run):
    result = CliRunner().invoke(app, ["query", str(tiny_run / "spec.toml"), "select job from jobs", "--limit", "2"])
    assert result.exit_code == 0, result.output
    assert "first 2 rows shown" in result.output


@pytest.mark.parametrize("suffix", [".csv", ".json", ".parquet"])
def test_query_output_files_hold_every_row(tiny_run, tmp_path, suffix):
    expected = _results_count(tiny_run)
    out = tmp_path / "out" / f"results{suffix}"
    result = CliRunner().invoke(
        app, ["query", str(tiny_run / "spec.toml"), "select job, object, correct from results;",
              "--output", str(out), "--limit", "1"]
    )
    assert result.exit_code == 0, result.output
    if suffix == ".csv":
        with open(out, newline="") as fh:
            rows = list(csv.DictReader(fh))
        assert len(rows) == expected and set(rows[0]) == {"job", "object", "correct"}
    elif suffix == ".json":
        rows = json.loads(out.read_text())
        assert len(rows) == expected and rows[0]["object"] == "box"
    else:
        assert pq.read_table(out).num_rows == expected


def test_a_run_merges_a_table_grown_past_the_segment_limit(tmp_path: Path) -> None:
    from sweep3d.runner.pipeline import compact_crowded_tables

    store = Store(tmp_path / "store")
    for i in range(7):
        store.append("renders", [render_row(f"k{i}")])
    store.append("images", [])  # nothing written: no segment
    with store.lock():
        assert compact_crowded_tables(store, limit=8) == []  # within the limit: left alone
        assert len(store.readable_segments("renders")) == 7
        for i in range(7, 12):
            store.append("renders", [render_row(f"k{i}")])
        assert compact_crowded_tables(store, limit=8) == ["renders"]
    assert len(store.readable_segments("renders")) == 1
    assert store.keys("renders") == {f"k{i}" for i in range(12)}


# -- sweep3d query is read-only ----------------------------------------------------------------

RESULTS = 40  # synthetic results in the store of the query tests (no Blender, no model)


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory) -> Path:
    """A spec and its store holding synthetic results (see benchmarks/report_scale.py)."""
    from tests.helpers import build_store

    return build_store(tmp_path_factory.mktemp("query"), RESULTS)






@pytest.mark.parametrize("sql, text", [
    ("COPY (SELECT 42) TO '{store}/x.csv'", "refused COPY:"),
    ("COPY results TO '{store}/tables/predictions/x.parquet'", "refused COPY:"),
    ("ATTACH '{store}/x.duckdb' AS db", "refused ATTACH:"),
    ("EXPORT DATABASE '{store}/dump'", "refused EXPORT:"),
    ("INSTALL httpfs", "refused LOAD:"),
    ("LOAD httpfs", "refused LOAD:"),
    ("SET enable_external_access = true", "refused SET:"),
    ("SELECT 1; COPY (SELECT 42) TO '{store}/x.csv'", "refused 2 statements"),
    ("SELECT * FROM read_csv('/etc/passwd')", "file system operations are disabled"),
    ("SELECT * FROM read_text('{spec}')", "file system operations are disabled"),
    ("SELECT * FROM glob('{store}/*')", "file system operations are disabled"),
    ("SELECT count(*) FROM read_parquet('{store}/../*.parquet')", "file system operations are disabled"),
])
def test_query_refuses_to_write_or_read_outside_the_store_in_one_line(synthetic: Path, sql: str, text: str) -> None:
    store = synthetic.parent / "store"
    before = store_tree(store)
    result = CliRunner().invoke(app, ["query", str(synthetic), sql.format(store=store, spec=synthetic)])
    assert result.exit_code == 2, result.output
    assert text in one_line(result.output) and "Traceback" not in result.output
    assert store_tree(store) == before
    assert sorted(p.name for p in synthetic.parent.iterdir()) == ["cube.obj", "spec.toml", "store"]


def test_query_reads_the_views_and_the_stores_own_segments(synthetic: Path) -> None:
    segment = Store(synthetic.parent / "store").segments("predictions")[0]
    sql = f"SELECT (SELECT count(*) FROM results) AS n, (SELECT count(*) FROM read_parquet('{segment}')) AS m"
    result = CliRunner().invoke(app, ["query", str(synthetic), sql])
    assert result.exit_code == 0, result.output
    assert f"│ {RESULTS} │ {RESULTS} │" in result.output


@pytest.mark.parametrize("suffix", [".csv", ".json", ".parquet"])
def test_query_output_still_writes_every_row_and_nothing_else(synthetic: Path, tmp_path: Path, suffix: str) -> None:
    store = synthetic.parent / "store"
    before = store_tree(store)
    out = tmp_path / "out" / f"rows{suffix}"
    sql = "SELECT job, object, correct FROM results ORDER BY job -- a comment ends the statement;"
    result = CliRunner().invoke(app, ["query", str(synthetic), sql, "--output", str(out)])
    assert result.exit_code == 0, result.output
    if suffix == ".csv":
        with open(out, newline="") as fh:
            rows = list(csv.DictReader(fh))
    elif suffix == ".json":
        rows = json.loads(out.read_text())
    else:
        rows = pq.read_table(out).to_pylist()
    assert len(rows) == RESULTS and set(rows[0]) == {"job", "object", "correct"}
    assert [p.name for p in out.parent.iterdir()] == [out.name]  # no temp file left beside it
    assert store_tree(store) == before


@pytest.mark.parametrize("sql", [
    "COPY (SELECT 42) TO '{store}/x.csv'",
    "ATTACH '{store}/x.duckdb' AS db",
    "SET allowed_directories = ['/']",
    "SELECT * FROM read_csv('/etc/passwd')",
])
def test_a_read_only_connection_refuses_what_the_query_filter_lets_through(synthetic: Path, sql: str) -> None:
    """The second line of defence: the connection itself, should a statement get past the filter.
    (It cannot stop writes to the files the views read: DuckDB's allow-list is for both.)"""
    from sweep3d.results import connect

    store = Store(synthetic.parent / "store")
    before = store_tree(store.root)
    con = connect(store, "scale", read_only=True)
    assert con.execute("SELECT count(*) FROM results").fetchone()[0] == RESULTS
    with pytest.raises(duckdb.Error, match="disabled by configuration|configuration has been locked"):
        con.execute(sql.format(store=store.root))
    assert store_tree(store.root) == before


def test_a_failed_export_leaves_no_file(synthetic: Path, tmp_path: Path) -> None:
    out = tmp_path / "rows.csv"
    result = CliRunner().invoke(app, ["query", str(synthetic), "SELECT nope FROM results", "--output", str(out)])
    assert result.exit_code == 2 and "query failed" in one_line(result.output)
    assert list(tmp_path.iterdir()) == []


def test_query_never_cuts_values_whatever_the_terminal_width(synthetic: Path) -> None:
    """Many wide columns in 80 columns: records instead of a table of "…"; csv and json whole."""
    long = "x" * 150
    sql = (f"SELECT '{long}' AS long_value, 1.0/3 AS third, job, object, environment, correct, valid, "
           "render_key, image_key, pred_key FROM results ORDER BY job LIMIT 2")
    result = CliRunner().invoke(app, ["query", str(synthetic), sql], env={"COLUMNS": "80"})
    assert result.exit_code == 0, result.output
    assert "…" not in result.output and long in result.output.replace("\n", "")
    assert result.output.count("-- row ") == 2 and "render_key: " in result.output
    wide = CliRunner().invoke(app, ["query", str(synthetic), sql, "--format", "table"], env={"COLUMNS": "400"})
    assert "┃ long_value" in wide.output and "…" not in wide.output
    as_csv = CliRunner().invoke(app, ["query", str(synthetic), sql, "--format", "csv"], env={"COLUMNS": "80"})
    header, first, second = as_csv.output.strip().splitlines()
    assert header.startswith("long_value,third,job") and first.startswith(f"{long},0.333333")
    as_json = CliRunner().invoke(app, ["query", str(synthetic), sql, "--format", "json"])
    assert [row["long_value"] for row in json.loads(as_json.output)] == [long, long]
    bad = CliRunner().invoke(app, ["query", str(synthetic), "SELECT 1", "--format", "xml"])
    assert bad.exit_code == 2 and "--format 'xml': use one of" in one_line(bad.output)


@pytest.mark.parametrize("value", ["[/x]", "[bold red]x", "[link=https://example.com]click[/link]", "a\\tb"])
def test_query_prints_values_as_text_never_as_markup(synthetic: Path, value: str) -> None:
    for form in ("table", "records"):
        result = CliRunner().invoke(app, ["query", str(synthetic), f"SELECT '{value}' AS v", "--format", form])
        assert result.exit_code == 0 and "Traceback" not in result.output, result.output
        assert value in result.stdout, (form, result.stdout)


def test_query_shows_control_characters_escaped_and_keeps_them_in_json(synthetic: Path) -> None:
    sql = "SELECT chr(27) || '[31mred' || chr(7) AS v"
    for form in ("table", "records", "csv"):  # CliRunner's stdout is no terminal: csv keeps the bytes
        result = CliRunner().invoke(app, ["query", str(synthetic), sql, "--format", form])
        assert result.exit_code == 0, result.output
        if form == "csv":
            assert "\x1b[31mred\x07" in result.stdout
        else:
            assert "\\x1b[31mred\\x07" in result.stdout and "\x1b" not in result.stdout
    result = CliRunner().invoke(app, ["query", str(synthetic), sql, "--format", "json"])
    assert json.loads(result.stdout) == [{"v": "\x1b[31mred\x07"}]


def test_machine_formats_print_every_row_and_notes_go_to_stderr(synthetic: Path) -> None:
    sql = "SELECT range AS i FROM range(120)"
    as_json = CliRunner().invoke(app, ["query", str(synthetic), sql, "--format", "json"])
    assert [row["i"] for row in json.loads(as_json.stdout)] == list(range(120)) and not as_json.stderr
    as_csv = CliRunner().invoke(app, ["query", str(synthetic), sql, "--format", "csv"])
    assert len(list(csv.DictReader(as_csv.stdout.splitlines()))) == 120
    table = CliRunner().invoke(app, ["query", str(synthetic), sql, "--format", "table"])
    assert "first 50 rows shown" in table.stderr and "first 50 rows shown" not in table.stdout


def test_help_texts_print_table_names_in_brackets() -> None:
    result = CliRunner().invoke(app, ["bench", "--help"])
    assert result.exit_code == 0 and "spec's [render]" in " ".join(result.output.split())


def test_query_output_on_a_full_disk_is_the_disk_not_the_sql(synthetic: Path, tmp_path: Path, monkeypatch) -> None:
    """A real ENOSPC (the temp file is /dev/full): one line saying the disk is full and to write
    elsewhere, without the SQL hint a failed query gets, nor advice to move the store."""
    import importlib

    monkeypatch.setattr(importlib.import_module("sweep3d.cli.app").uuid, "uuid4", FixedUuid)
    out = tmp_path / "rows.csv"
    (tmp_path / ".rows.csv.fixed.tmp").symlink_to("/dev/full")
    store = synthetic.parent / "store"
    before = store_tree(store)
    result = CliRunner().invoke(app, ["query", str(synthetic), "SELECT * FROM results", "--output", str(out)])
    line = one_line(result.output)
    assert result.exit_code == 2, result.output
    assert line.startswith(f"error: cannot write --output {out}: the disk is full (No space left on device; "), line
    assert line.endswith("free some disk space, or write it to another disk"), line
    assert "docs/how-to/query.md" not in line and "experiment.store" not in line
    assert list(tmp_path.iterdir()) == [] and store_tree(store) == before  # the link to /dev/full removed, not it
    assert Path("/dev/full").exists()


@pytest.mark.parametrize("width", [60, 80, 120])
def test_a_table_too_wide_for_the_terminal_is_folded_into_tables_of_whole_columns(synthetic: Path,
                                                                                  width: int) -> None:
    """``--format table`` on ``SELECT * FROM runs``: it drew a grid of one-letter slivers with no
    header or value readable; now a table per group of columns that fits, headers whole, every
    value there, rows numbered so the tables line up."""
    sql = "SELECT * EXCLUDE (spec) FROM runs"
    result = CliRunner().invoke(app, ["query", str(synthetic), sql, "--format", "table"], env={"COLUMNS": str(width)})
    assert result.exit_code == 0, result.output
    columns = json.loads(CliRunner().invoke(app, ["query", str(synthetic), sql, "--format", "json"]).output)[0]
    lines = result.output.splitlines()
    assert all(len(line) <= width for line in lines)
    assert all(f"┃ {name} " in result.output for name in columns), result.output  # every header whole
    titles = [line.strip() for line in lines if line.strip().startswith(("columns ", "column "))]
    assert len(titles) > 1 and titles[-1].endswith(f"{len(columns)} of {len(columns)}"), titles
    assert "│ synthetic0 " in result.output and "│ 1 │" in result.output
