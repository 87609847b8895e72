"""The store knows a table only by its contract: its key, its columns, which row of a key counts
and the files its rows keep, registered by the package that writes it. The cache layer names no
package above it, and every command sees every declared table whatever it imported."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from datetime import datetime, timedelta
from pathlib import Path

import pytest

from sweep3d.cache import (
    KeptFiles,
    Store,
    TableContract,
    collect_garbage,
    compact_table,
    contract_of,
    register_table,
    store_stats,
    table_names,
    unregister_table,
    verify,
)
from tests.helpers import REPO

CACHE = REPO / "sweep3d" / "cache"
#: What the packages above the store are called: the store's code names none of them, in code,
#: strings, comments or docstrings.
ABOVE = ("followups", "stability", "explain", "confirm", "realism", "verdict")
T0 = datetime(2024, 1, 1)


def test_the_cache_layer_names_no_follow_up() -> None:
    named = [f"{path.relative_to(REPO)}:{n}: {line.strip()}" for path in sorted(CACHE.glob("*.py"))
             for n, line in enumerate(path.read_text().splitlines(), 1)
             if re.search("|".join(ABOVE), line, re.IGNORECASE)]
    assert not named, "the store knows keys and files only; declare a table in its package:\n" + "\n".join(named)


def test_every_declared_table_is_known_without_importing_its_package() -> None:
    """``cache verify`` run first in a process (nothing imported but the cache) sees the follow-ups'
    tables: the package root names their modules, imported when every table is asked for."""
    probe = ("import json, sys\nfrom sweep3d.cache import table_names\n"
             "before = sorted(m for m in sys.modules if m.startswith('sweep3d.followups.'))\n"
             "print(json.dumps([before, list(table_names())]))")
    out = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, check=True)
    before, names = json.loads(out.stdout.splitlines()[-1])
    assert before == [], "nothing of a follow-up is imported until a table of one is needed"
    assert {"stability", "verdicts", "confirmations", "counterfactuals"} <= set(names)
    assert names[:6] == ["renders", "images", "predictions", "runs", "parts", "truths"]


@pytest.fixture
def declared():
    """Register test tables for one test; forget them after."""
    names: list[str] = []

    def declare(contract: TableContract) -> TableContract:
        names.append(contract.name)
        return register_table(contract)

    yield declare
    for name in names:
        unregister_table(name)


@pytest.mark.parametrize("merge, wanted", [("newest", "late"), ("first", "early")])
def test_the_key_and_the_merge_rule_come_from_the_registry(tmp_path: Path, declared, merge: str, wanted: str) -> None:
    name = f"probe_{merge}"
    declared(TableContract(name, key="probe_id", columns=("probe_id", "value", "created_at"), merge=merge))
    assert name in table_names() and contract_of(name).key == "probe_id"
    store = Store(tmp_path / "store")
    store.append(name, [{"probe_id": "a", "value": "early", "created_at": T0},
                        {"probe_id": "b", "value": "only", "created_at": T0}])
    store.append(name, [{"probe_id": "a", "value": "late", "created_at": T0 + timedelta(days=1)}])

    assert store.key_set(name) == {"a", "b"}  # by the contract's key column
    view = dict(store.connect().execute(f"SELECT probe_id, value FROM {name}").fetchall())
    assert view == {"a": wanted, "b": "only"}  # the view keeps the row the merge rule says counts
    with store.lock():
        done = compact_table(store, name)
    assert done is not None and (done.rows_before, done.rows_after) == (3, 2)
    merged = {r["probe_id"]: r["value"] for r in store.table(name).to_pylist()}
    assert merged == {"a": wanted, "b": "only"}  # compaction keeps the same one
    assert any(s.name == name and (s.rows, s.keys) == (2, 2) for s in store_stats(store.root))


def test_a_table_s_kept_files_are_verified_collected_and_counted(tmp_path: Path, declared) -> None:
    """Kept files are the contract's: verify checks those a row names with its check, gc removes
    the ones no row names (never a file of another name), stats counts both."""
    kept = KeptFiles(folder=("notes", "kept"), column="note_sha256", suffix=".txt", noun="note",
                     check=lambda path: "" if path.read_text() == "ok" else "not ok",
                     missing_fix="write the note again", unnamed="no probe names")
    declared(TableContract("probe_kept", key="probe_id", columns=("probe_id", "created_at"), kept=kept))
    store = Store(tmp_path / "store")
    named, orphan = "a" * 64, "b" * 64
    store.append("probe_kept", [{"probe_id": "p", "note_sha256": named, "created_at": T0}])
    kept.path(store.root, named).parent.mkdir(parents=True)
    kept.path(store.root, named).write_text("ok")
    kept.path(store.root, orphan).write_text("ok")
    mine = kept.path(store.root, named).parent / "mine.txt"
    mine.write_text("the user's")

    report = verify(store.root)
    assert report.ok and report.kept[kept] == 1
    assert any(s.name == "kept notes" and (s.files, s.keys) == (3, 1) for s in store_stats(store.root))

    kept.path(store.root, named).write_text("damaged")
    report = verify(store.root)
    assert [(p.kind, p.table, p.key, p.detail) for p in report.problems] == [
        ("corrupt kept note", "probe_kept", named, "not ok")]
    kept.path(store.root, named).unlink()
    assert [(p.kind, p.detail) for p in verify(store.root).problems] == [("missing kept note", "write the note again")]

    with store.lock():
        out = collect_garbage(store.root)
    assert out.kept[kept] == 1 and not kept.path(store.root, orphan).exists() and mine.exists()


@pytest.mark.parametrize("bad, why", [
    (dict(name="x", key="id", columns=("other",)), "key 'id' is not among its columns"),
    (dict(name="x", key="id", columns=("id",), merge="last"), "merge is one of"),
    (dict(name="../x", key="id", columns=("id",)), "a table's name is"),
    (dict(name="jobs", key="id", columns=("id",)), "a table's name is"),
    (dict(name="x", key="id; DROP", columns=("id; DROP",)), "key column is named"),
])
def test_a_contract_that_cannot_be_kept_is_refused(bad: dict, why: str) -> None:
    with pytest.raises(ValueError, match=re.escape(why)):
        TableContract(**bad)


def test_a_table_declared_twice_differently_is_refused(declared) -> None:
    declared(TableContract("probe_twice", key="id", columns=("id",)))
    declared(TableContract("probe_twice", key="id", columns=("id",)))  # the same again: a no-op
    with pytest.raises(ValueError, match="already declared"):
        register_table(TableContract("probe_twice", key="id", columns=("id",), merge="newest"))
    with pytest.raises(ValueError, match="already declared"):
        register_table(TableContract("renders", key="id", columns=("id",)))
    with pytest.raises(KeyError, match="no table 'probe_none'"):
        contract_of("probe_none")
