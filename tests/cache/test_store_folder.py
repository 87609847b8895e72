"""Which folders may be a store (issue 45, item 7): a system folder, a top-level folder, the home
folder, a file or a folder holding other files is refused at load in one line naming
``experiment.store``, exit code 2, nothing written; a new, empty or store's folder is taken. And
``worker_jobs`` is bounded."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cache import Store
from sweep3d.cache.store_folder import STORE_MADE, store_folder_problem
from sweep3d.cli import app
from tests.helpers import TINY_SPEC, write_spec


def _with_store(folder: Path, store: str) -> Path:
    return write_spec(folder, TINY_SPEC.replace('store = "store"', f"store = {store!r}".replace("'", '"'), 1))


def _listing(folder: Path) -> list[tuple[str, int]]:
    return sorted((str(p.relative_to(folder)), p.stat().st_mtime_ns) for p in folder.rglob("*"))


SYSTEM = [("/", "top-level folder"), ("/etc", "top-level folder"), ("/proc/self", "inside the system folder '/proc'"),
          ("/etc/sweep3d-store", "inside the system folder '/etc'"), ("/usr/share/x", "inside the system folder '/usr'"),
          ("/tmp", "top-level folder")]


@pytest.mark.parametrize(("store", "phrase"), SYSTEM, ids=[s for s, _ in SYSTEM])
def test_a_system_folder_is_refused_in_one_line(tmp_path: Path, store: str, phrase: str) -> None:
    spec = _with_store(tmp_path, store)
    before = _listing(tmp_path)
    result = CliRunner().invoke(app, ["plan", str(spec)])
    assert result.exit_code == 2, result.output
    [line] = result.output.strip().splitlines()
    assert line.startswith(f"error: {spec}: experiment.store: ") and phrase in line and "new or empty folder" in line
    assert _listing(tmp_path) == before
    assert not Path("/etc/sweep3d-store").exists()


def test_a_folder_holding_other_files_is_refused_and_left_alone(tmp_path: Path) -> None:
    """``store = "."``: the spec's own folder (its spec and mesh) is not a store's."""
    spec = _with_store(tmp_path, ".")
    before = _listing(tmp_path)
    result = CliRunner().invoke(app, ["run", str(spec)])
    assert result.exit_code == 2, result.output
    [line] = result.output.strip().splitlines()
    assert "already holds other files (cube.obj, spec.toml) and no sweep3d store" in line, line
    assert _listing(tmp_path) == before


def test_a_file_and_the_home_folder_are_refused(tmp_path: Path, monkeypatch) -> None:
    (tmp_path / "a-file").write_text("x")
    assert "is a file, not a folder" in store_folder_problem(tmp_path / "a-file")
    home = tmp_path / "home" / "someone"
    (home / "Documents").mkdir(parents=True)
    monkeypatch.setenv("HOME", str(home))
    assert "is the home folder itself" in store_folder_problem(home)


def test_a_new_empty_or_stores_folder_is_taken(tmp_path: Path) -> None:
    assert store_folder_problem(tmp_path / "new" / "store") is None
    (tmp_path / "empty").mkdir()
    assert store_folder_problem(tmp_path / "empty") is None
    used = tmp_path / "used"
    with Store(used).lock():  # a store that was written to: its lock (a user's note beside it is fine)
        pass
    (used / "NOTES.txt").write_text("mine")
    assert store_folder_problem(used) is None
    planned = tmp_path / "planned"  # only planned: a zipped mesh extracted, nothing locked yet
    (planned / "assets" / "0123").mkdir(parents=True)
    assert store_folder_problem(planned) is None
    (planned / "README.md").write_text("not a store's")
    assert "already holds other files (README.md)" in store_folder_problem(planned)


def test_every_name_a_store_makes_at_its_top_is_known(tmp_path: Path) -> None:
    """What a run, a report, an export of results and the follow-ups leave at the store's top: a
    store made by sweep3d itself is never refused (the set is what the code writes there, and the
    folders of every declared table's kept files)."""
    from sweep3d.cache import ASSETS_FOLDER, OUTPUTS_FOLDER, table_contracts

    assert {ASSETS_FOLDER, OUTPUTS_FOLDER} <= STORE_MADE
    kept = [c.kept.folder for c in table_contracts() if c.kept is not None]
    assert kept  # the follow-ups' tables are declared without importing their packages
    for folder in kept:
        only = tmp_path / f"only-{folder[0]}"
        (only.joinpath(*folder)).mkdir(parents=True)
        assert store_folder_problem(only) is None, folder
    store = Store(tmp_path / "s")
    store.tmp_dir()
    store.report_path("x").parent.mkdir(parents=True)
    assert set(os.listdir(store.root)) <= STORE_MADE and store_folder_problem(store.root) is None


def test_worker_jobs_is_bounded(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, TINY_SPEC.replace("denoise = false\n", f"denoise = false\nworker_jobs = {2**70}\n", 1))
    result = CliRunner().invoke(app, ["plan", str(spec)])
    assert result.exit_code == 2, result.output
    [line] = result.output.strip().splitlines()
    assert f"{spec}: render.worker_jobs: " in line and "less than or equal to 1000000000" in line
