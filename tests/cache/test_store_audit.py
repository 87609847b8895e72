"""The store-robustness audit (issue 22), case by case: gc touches only what the store wrote, the
store's own files cannot be replaced by a query's export, a folder in a file's place, a segment
with another table's columns, a store the user may not read, and readers that must not repair.

Each mistake is one line and exit code 2 (never a traceback), and leaves the store as it was or
repaired. Stores are synthetic (no Blender, no model): cheap enough for the fast lane.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterator

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from sweep3d.cache.blobs import damaged_blobs, load_image
from sweep3d.cache.maintenance import verify
from sweep3d.cache.store import Store, StoreReadError, StoreWriteError
from sweep3d.cli import app
from tests.helpers import TINY_SPEC, add_render, one_line, render_row, store_tree, write_spec
from tests.helpers.users import as_user, hand_over

RESULTS = 24  # synthetic results in the stores these tests copy


def key(prefix: str) -> str:
    """A cache key as the store names blobs by (40 hex characters) beginning with ``prefix``."""
    return (prefix * 20)[:40]


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory) -> Path:
    """A folder holding a spec and its store of synthetic results (see benchmarks/report_scale.py)."""
    from tests.helpers import build_store

    return build_store(tmp_path_factory.mktemp("audit") / "run", RESULTS, images=False).parent


@pytest.fixture
def run_dir(synthetic: Path, tmp_path: Path) -> Path:
    """A private copy of the synthetic folder (spec.toml, store/) that a test may damage."""
    return Path(shutil.copytree(synthetic, tmp_path / "run"))


def cli(folder: Path, *args: str) -> tuple[int, str]:
    """``sweep3d ARGS`` run from ``folder`` (``SPEC``: its spec's path): (exit code, output)."""
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        result = CliRunner().invoke(app, [a if a != "SPEC" else str(folder / "spec.toml") for a in args])
    finally:
        os.chdir(cwd)
    return result.exit_code, result.output


def saved(root: Path) -> dict[str, tuple[int, int]]:
    """The store's files that hold data (tables, jobs, blobs, quarantine; not the lock, reports
    or caches), as they are."""
    return {name: state for name, state in store_tree(root).items()
            if name.split(os.sep)[0] in ("tables", "jobs", "blobs", "quarantine")}


def one_error(code: int, output: str) -> str:
    """The one line a user mistake prints (exit code 2, no traceback)."""
    assert code == 2, output
    line = one_line(output)
    assert line.startswith("error: ") and "Traceback" not in output, output
    return line


def warnings_of(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "sweep3d.store"]


def damage_a_segment(root: Path) -> Path:
    """A renders segment whose bytes are garbage (as the audit planted one)."""
    bad = Store(root).append("renders", [render_row(key("ab"))])
    bad.write_bytes(os.urandom(300))
    return bad


#: Every command that reads the store (the permission tests run each one).
READ_COMMANDS = [["plan", "SPEC"], ["run", "SPEC"], ["report", "SPEC"], ["query", "SPEC", "select 1"],
                 ["cache", "verify", "SPEC"], ["cache", "stats", "SPEC"], ["cache", "gc", "SPEC"],
                 ["cache", "compact", "SPEC"]]


@pytest.fixture(scope="module")
def warmed(synthetic: Path, tmp_path_factory) -> None:
    """Every command, once, as this process's user: a child that dropped root's privileges may
    not be able to read the standard library (where root installed Python), so it must import
    nothing new. ``run`` stops at a folder in the lock's place, before it would render."""
    folder = Path(shutil.copytree(synthetic, tmp_path_factory.mktemp("warm") / "run"))
    for command in sorted(READ_COMMANDS, key=lambda c: c[0] == "run"):  # run last
        if command[0] == "run":
            (folder / "store" / "lock").unlink(missing_ok=True)
            (folder / "store" / "lock").mkdir()
        cli(folder, *command)


@pytest.fixture
def shared_dir(synthetic: Path, warmed: None) -> Iterator[Path]:
    """A copy of the synthetic folder that the unprivileged user of :func:`as_user` owns, outside
    pytest's temp folder (which only its owner may enter)."""
    folder = Path(tempfile.mkdtemp(prefix="sweep3d-audit-")) / "run"
    shutil.copytree(synthetic, folder)
    try:
        hand_over(folder)
        yield folder
    finally:
        shutil.rmtree(folder.parent)  # as root, or as the owner of everything in it


# -- 6: gc deletes only what the store wrote, never through a symbolic link -------------------


def test_gc_leaves_foreign_files_and_symlinked_folders_alone(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, TINY_SPEC)
    root = tmp_path / "store"
    store = Store(root)
    add_render(store, key("aa"))
    orphan = store.blob_path(key("ff"))
    orphan.parent.mkdir(parents=True)
    orphan.write_bytes(b"a killed run's blob")
    holiday = orphan.with_name("holiday.png")
    holiday.write_bytes(b"a user's photo")
    outside = tmp_path / "outside"
    (outside / "sub").mkdir(parents=True)
    target_blob = outside / f"{key('cd')}.png"  # named as an unreferenced blob of blobs/cd/
    target_blob.write_bytes(b"not the store's")
    (outside / "sub" / ".x.png.dead.tmp").write_bytes(b"not the store's")
    (root / "blobs" / "cd").symlink_to(outside, target_is_directory=True)
    (root / "blobs" / "aa" / "linked").symlink_to(outside / "sub", target_is_directory=True)
    (root / "blobs" / "ff" / f"{key('fe')}.png").symlink_to(target_blob)
    (root / "quarantine").mkdir()
    (root / "quarantine" / "linked").symlink_to(outside, target_is_directory=True)
    before = sorted(p.name for p in outside.rglob("*"))

    code, output = cli(tmp_path, "cache", "gc", str(spec), "--older-than", "0", "--purge-quarantine")

    assert code == 0 and " ".join(output.split()).startswith("removed 1 unreferenced blobs, 0 temp"), output
    assert not orphan.exists() and holiday.read_bytes() == b"a user's photo"
    assert store.blob_path(key("aa")).is_file()
    assert sorted(p.name for p in outside.rglob("*")) == before and target_blob.read_bytes() == b"not the store's"
    assert all(link.is_symlink() for link in (root / "blobs" / "cd", root / "blobs" / "aa" / "linked",
                                               root / "quarantine" / "linked"))
    assert verify(root).ok


def test_gc_refuses_when_it_cannot_read_a_segment_instead_of_deleting_its_blobs(shared_dir: Path) -> None:
    """A segment gc may not read would make every blob of its rows look unreferenced."""
    root = shared_dir / "store"
    add_render(Store(root), key("aa"))
    hand_over(shared_dir)
    [segment] = Store(root).segments("renders")
    segment.chmod(0)
    before = saved(root)
    line = one_error(*as_user(lambda: cli(shared_dir, "cache", "gc", "SPEC")))
    assert line.startswith(f"error: gc removed nothing: tables/renders/{segment.name} is unreadable "
                           "(Permission denied; fix its permissions)"), line
    assert saved(root) == before


# -- 8: the store's own files ------------------------------------------------------------------


@pytest.mark.parametrize("output", ["store/jobs/scale.parquet", "link/jobs/scale.parquet", "store/x.csv"])
def test_query_refuses_to_write_its_output_inside_the_store(run_dir: Path, output: str) -> None:
    (run_dir / "link").symlink_to(run_dir / "store", target_is_directory=True)
    before = store_tree(run_dir / "store")
    line = one_error(*cli(run_dir, "query", "SPEC", "select count(*) from results", "-o", output))
    assert f"--output {output}: inside the store" in line
    assert store_tree(run_dir / "store") == before
    code, rows = cli(run_dir, "query", "SPEC", "select count(*) as n from results", "--format", "csv")
    assert code == 0 and rows.split() == ["n", str(RESULTS)], rows


def test_verify_reports_files_whose_columns_are_not_their_tables(run_dir: Path, caplog) -> None:
    """The jobs file a query export replaced, and another table's segment among the renders."""
    root = run_dir / "store"
    pq.write_table(pa.table({"count_star()": [RESULTS]}), root / "jobs" / "scale.parquet")
    [predictions] = Store(root).segments("predictions")
    stray = Store(root).table_dir("renders") / predictions.name
    stray.parent.mkdir(parents=True)
    shutil.copy(predictions, stray)

    code, output = cli(run_dir, "cache", "verify", "SPEC")
    assert code == 2, output
    problems = " ".join(output.split()).split(" corrupt ")[1:]  # the lines it prints wrap on a narrow terminal
    assert problems[0] == (f"segment: tables/renders/{stray.name} (its columns are not the renders table's: it has "
                           "no render_key column)")
    assert problems[1].startswith("jobs table: jobs/scale.parquet (its columns are not the jobs table's: it has no "
                                  "pred_key column) 2 problems;"), output
    before = saved(root)
    line = one_error(*cli(run_dir, "query", "SPEC", "select count(*) from results"))  # no answer without their rows
    assert line.startswith(f"error: cannot read {stray} (its columns are not the renders table's: it has no "
                           "render_key column) (and 1 more): no answer is given"), line
    assert saved(root) == before and warnings_of(caplog) == []  # one line, not a warning before it


@pytest.mark.parametrize("place", ["segment", "jobs"])
def test_a_folder_in_a_files_place_is_read_around_reported_and_repaired(run_dir: Path, place: str,
                                                                        caplog) -> None:
    root = run_dir / "store"
    folder = (root / "jobs" / "scale.parquet" if place == "jobs"
              else Store(root).table_dir("predictions") / "00000000000000000000-1-abcdef12.parquet")
    folder.unlink(missing_ok=True)
    folder.mkdir()
    (folder / "kept").write_text("a user's file")
    before = saved(root)

    code, output = cli(run_dir, "report", "SPEC")
    assert (code == 0) if place == "segment" else ("no results" in one_error(code, output)), output
    [warning] = warnings_of(caplog)
    assert f"{folder.name} is unreadable (a folder, not a file); skipping it" in warning
    assert saved(root) == before

    code, output = cli(run_dir, "cache", "verify", "SPEC", "--repair")
    assert code == 0 and "repaired 1 problems" in output, output
    assert (root / "quarantine" / folder.relative_to(root) / "kept").read_text() == "a user's file"
    assert verify(root).ok


@pytest.mark.parametrize("command", [["cache", "gc", "SPEC"], ["cache", "compact", "SPEC"], ["run", "SPEC"]],
                         ids=" ".join)
def test_a_folder_in_the_lock_files_place_is_one_line(run_dir: Path, command: list[str]) -> None:
    root = run_dir / "store"
    (root / "lock").mkdir()
    before = saved(root)
    line = one_error(*cli(run_dir, *command))
    assert line == f"error: cannot write {root / 'lock'} (Is a directory); a folder is where the store keeps a " \
                   "file: move it away", line
    assert saved(root) == before


@pytest.mark.parametrize("keep_same", [True, False])  # the jobs file (as a run writes it), a segment
def test_writing_where_a_folder_is_is_one_line_and_leaves_no_temp_file(tmp_path: Path, keep_same: bool) -> None:
    """What a run meets when it writes its plan over a folder in the jobs file's place."""
    store = Store(tmp_path / "store")
    path = store.jobs_path("exp")
    (path / "kept").mkdir(parents=True)
    with pytest.raises(StoreWriteError) as raised:
        store.write_table_file(path, pa.table({"pred_key": ["k"]}), keep_same=keep_same)
    assert str(raised.value) == (f"cannot write {path}: Is a directory; a folder is where the store keeps a file: "
                                 "move it away")
    assert sorted(p.name for p in path.parent.iterdir()) == ["exp.parquet"] and (path / "kept").is_dir()


# -- 9: a store the user may not read ----------------------------------------------------------

@pytest.mark.parametrize("denied", ["store", "store/tables"])
@pytest.mark.parametrize("command", READ_COMMANDS, ids=lambda c: " ".join(c[:2]))
def test_a_store_the_user_may_not_read_is_one_line(shared_dir: Path, command: list[str], denied: str) -> None:
    root = shared_dir / "store"
    before = saved(root)
    (shared_dir / denied).chmod(0)
    try:
        line = one_error(*as_user(lambda: cli(shared_dir, *command)))
    finally:
        (shared_dir / denied).chmod(0o755)
    assert str(shared_dir / denied) in line and "(Permission denied); fix its permissions" in line, line
    assert saved(root) == before


@pytest.mark.parametrize("denied", ["store", "store/tables"])
def test_a_store_folder_the_user_may_enter_but_not_list_works_or_is_one_line(shared_dir: Path, denied: str) -> None:
    """``chmod u-r``: what needs no listing of it still works; what does is one line."""
    root = shared_dir / "store"
    before = saved(root)
    commands = [c for c in READ_COMMANDS if c[0] != "run"]  # a run would render
    (shared_dir / denied).chmod(0o300)
    try:
        results = as_user(lambda: [cli(shared_dir, *command) for command in commands])
    finally:
        (shared_dir / denied).chmod(0o755)
    refused = [command[-2 if command[0] == "cache" else 0] for command, (code, output) in zip(commands, results)
               if code and f"cannot read {shared_dir / denied} (Permission denied)" in one_error(code, output)]
    assert all(code == 0 for command, (code, _) in zip(commands, results) if command[-2:][0] not in refused)
    assert refused == ([] if denied == "store" else ["gc"]), results
    assert saved(root) == before


def test_an_unreadable_spec_is_one_line(shared_dir: Path) -> None:
    spec = shared_dir / "spec.toml"
    spec.chmod(0)
    line = one_error(*as_user(lambda: cli(shared_dir, "plan", "SPEC")))
    assert line == f"error: {spec}: cannot read the spec (Permission denied); fix its permissions", line


def test_a_blob_the_user_may_not_read_is_one_line_not_damaged_and_not_made_again() -> None:
    """A run checks the blobs it counts as cached, and stages read their inputs: one the OS will
    not let it read was called damaged, quarantined and made again; now it is named, with the
    OS's reason, and left as it is (issue 35, item 15b)."""
    folder = Path(tempfile.mkdtemp(prefix="sweep3d-audit-")) / "run"
    root = folder / "store"
    try:
        add_render(Store(root), key("ab"))
        blob = Store(root).blob_path(key("ab"))
        hand_over(folder)
        blob.chmod(0)
        before = saved(root)

        def read() -> list[str]:
            lines = []
            for call in (lambda: damaged_blobs(Store(root), "renders", {key("ab")}),
                         lambda: load_image(Store(root), key("ab"), None)):
                try:
                    lines.append(f"no error: {call()}")
                except StoreReadError as exc:
                    lines.append(str(exc))
            return lines

        lines = as_user(read)
        after = saved(root)
    finally:
        shutil.rmtree(folder.parent)
    for line in lines:
        assert line == (f"cannot read {blob} (Permission denied); fix its permissions (a blob that cannot be read is "
                        "not damaged: sweep3d leaves it, and its results, as they are)"), lines
    assert after == before  # neither quarantined nor its row dropped


def test_verify_names_what_it_may_not_read_and_repair_moves_only_what_is_damaged(shared_dir: Path) -> None:
    """Issue 45, item 1: ``verify`` called an intact blob the OS would not let it read corrupt and
    advised ``--repair``, which moved it (and dropped its row) into quarantine. Run as a user the
    permissions hold for: such a blob, and such a segment, are named unreadable and left as they
    are, with their rows; a blob whose bytes are wrong beside them is still quarantined. Problems
    exit 2."""
    root = shared_dir / "store"
    store = Store(root)
    earlier = set(store.segments("renders"))
    add_render(store, key("ab"))  # intact, but the user may not read it
    [its_rows] = set(store.segments("renders")) - earlier
    add_render(store, key("cd"))  # its bytes damaged
    refused, damaged = store.blob_path(key("ab")), store.blob_path(key("cd"))
    damaged.write_bytes(b"not the PNG it was")
    segment = store.append("renders", [render_row(key("ef"))])  # a segment the user may not read
    hand_over(shared_dir)
    refused.chmod(0)
    segment.chmod(0)
    kept = [str(p.relative_to(root)) for p in (refused, its_rows, segment)]
    before = saved(root)
    try:
        (code, output), (repair_code, repaired) = as_user(lambda: [
            cli(shared_dir, "cache", "verify", "SPEC"), cli(shared_dir, "cache", "verify", "SPEC", "--repair")])
    finally:
        refused.chmod(0o644)
        segment.chmod(0o644)
    after = saved(root)
    output, repaired = " ".join(output.split()), " ".join(repaired.split())

    assert code == 2, output
    blob, damaged_name = refused.relative_to(root), damaged.relative_to(root)
    assert f"unreadable blob: {blob} (Permission denied; fix its permissions)" in output, output
    assert f"unreadable segment: {segment.relative_to(root)} (Permission denied; fix its permissions)" in output
    assert f"corrupt blob: {damaged_name} (content does not match its recorded SHA-256)" in output, output
    assert f"corrupt blob: {blob}" not in output and "corrupt segment" not in output, output
    assert "1 problems; run: sweep3d cache verify" in output and "2 files cannot be read" in output, output
    assert repair_code == 2 and "repaired 1 problems" in repaired and "2 files cannot be read" in repaired, repaired
    assert {name: after.get(name) for name in kept} == {name: before[name] for name in kept}  # in place, unchanged
    assert sorted(after.keys() - before.keys()) == [f"quarantine/{damaged_name}"], after.keys() - before.keys()
    assert key("ab") in Store(root).keys("renders") and key("cd") not in Store(root).keys("renders")


# -- 10: readers read around a damaged segment; only the lock's holder repairs -----------------


@pytest.mark.parametrize("command", [["plan", "SPEC"], ["report", "SPEC"]], ids=lambda c: c[0])
def test_readers_warn_once_and_leave_a_damaged_segment_in_place(run_dir: Path, command: list[str],
                                                                  caplog) -> None:
    root = run_dir / "store"
    bad = damage_a_segment(root)
    before = saved(root)
    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        code, output = cli(run_dir, *command)
    assert code == 0, output
    [warning] = warnings_of(caplog)
    assert f"tables/renders/{bad.name} is unreadable" in warning and "skipping it" in warning
    assert "\n" not in warning and saved(root) == before  # nothing moved to quarantine/


def test_a_query_refuses_an_answer_without_a_damaged_segments_rows(run_dir: Path, caplog) -> None:
    """A query read around a damaged segment answered with the rows of the others after a warning:
    96 of 160 results read as the whole answer (issue 45, item 9). It is refused in one line
    naming the segment and the repair; the store is left as it was."""
    import sweep3d

    root = run_dir / "store"
    bad = damage_a_segment(root)
    before = saved(root)
    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        line = one_error(*cli(run_dir, "query", "SPEC", "select count(*) from results"))
    assert line.startswith(f"error: cannot read {bad} (") and "no answer is given" in line, line
    assert line.endswith(f"run: sweep3d cache verify {run_dir / 'spec.toml'} --repair (it moves the file aside; "
                         "the next run computes its rows again)"), line
    assert warnings_of(caplog) == [] and saved(root) == before
    with pytest.raises(StoreReadError, match=f"cannot read {bad}"):
        sweep3d.load(run_dir / "spec.toml").sql("select count(*) from results")


@pytest.mark.parametrize("denied, command", [
    ("store/jobs", ["query", "SPEC", "select count(*) from results"]),
    ("store/jobs", ["confirm", "SPEC"]),
    ("store/blobs", ["export", "SPEC", "--format", "imagefolder", "--where", "true", "-o", "exported"]),
], ids=lambda v: v if isinstance(v, str) else v[0])
def test_an_unreadable_jobs_or_blobs_folder_is_one_line(shared_dir: Path, denied: str, command: list[str]) -> None:
    """Each was a PermissionError traceback (``Path.exists`` raises for a folder that denies it)."""
    root = shared_dir / "store"
    (root / "blobs").mkdir(exist_ok=True)
    hand_over(shared_dir)
    before = saved(root)
    (shared_dir / denied).chmod(0)
    try:
        line = one_error(*as_user(lambda: cli(shared_dir, *command)))
    finally:
        (shared_dir / denied).chmod(0o755)
    assert line.startswith(f"error: cannot read {shared_dir / denied} (Permission denied)"), line
    assert "fix its permissions" in line and saved(root) == before
    assert not (shared_dir / "exported").exists()


def test_only_the_lock_holder_quarantines_a_damaged_segment(run_dir: Path, caplog) -> None:
    root = run_dir / "store"
    bad = damage_a_segment(root)
    assert Store(root).keys("renders") == set() and bad.exists()
    with Store(root).lock():
        assert Store(root).keys("renders") == set()  # any store object of the holding process
    assert not bad.exists() and (root / "quarantine" / "tables" / "renders" / bad.name).is_file()
    [skipped, moved] = warnings_of(caplog)
    assert "skipping it" in skipped and "moved it to quarantine/" in moved


def test_counterfactuals_the_user_may_not_read_are_named_not_a_missing_table(shared_dir: Path) -> None:
    """``explain``'s rows made unreadable (a segment of its table, or a store's file from before the
    table): one line naming it and the fix, not DuckDB's "Table with name counterfactuals does not
    exist"; a store that was never explained still has no such view."""
    from sweep3d.followups.explain import write_counterfactuals
    from sweep3d.results import SCHEMA, legacy_counterfactuals_path

    sql = "SELECT count(*) FROM counterfactuals"
    assert "counterfactuals does not exist" in one_error(*cli(shared_dir, "query", "SPEC", sql))  # never explained
    store = Store(shared_dir / "store")
    path = legacy_counterfactuals_path(store, "scale")
    path.parent.mkdir()
    pq.write_table(pa.Table.from_pylist([], schema=SCHEMA), path)
    hand_over(shared_dir)
    assert cli(shared_dir, "query", "SPEC", sql)[0] == 0  # readable: the view, empty
    path.chmod(0)
    line = one_error(*as_user(lambda: cli(shared_dir, "query", "SPEC", sql)))
    assert line == f"error: cannot read {path} (Permission denied); fix its permissions", line

    row = {name: None for name in SCHEMA.names} | {"experiment": "scale", "failure_pred_key": "p", "failure_job": 0}
    write_counterfactuals(store, "scale", [row])  # explain again: its table's rows, the older file gone
    [segment] = store.segments("counterfactuals")
    assert not path.exists()
    hand_over(shared_dir)
    segment.chmod(0)
    line = one_error(*as_user(lambda: cli(shared_dir, "query", "SPEC", sql)))
    assert line.startswith(f"error: cannot read {segment} (Permission denied)") and "fix its permissions" in line, line
