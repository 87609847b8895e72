"""The ``verdicts`` table and the kept photographs (``sweep3d realism score``) are the store's
like any table: ``cache stats`` counts them, ``cache verify`` reads the segments and decodes
the kept photos (and ``--repair`` quarantines a damaged one), ``cache compact`` keeps each
verdict's newest row (a job scored again), and ``cache gc`` removes kept photos no verdict names,
never a file the user put there. The store is the realism tests' synthetic one: no model runs.
"""

from __future__ import annotations

import os
import time
from datetime import timedelta
from pathlib import Path

from typer.testing import CliRunner

from sweep3d.cache import TABLES, Store
from sweep3d.cli import app
from sweep3d.followups.realism.photos import photo_like
from sweep3d.results.agreement import VERDICT_SCHEMA, VERDICTS, photo_path
from tests.helpers.realism import T1, image_of, make_run, verdict


def cache(spec: Path, *args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, ["cache", *args, str(spec)])
    return result.exit_code, result.output


def flat(output: str) -> str:
    """The output with the lines a narrow console wraps joined again."""
    return output.replace("\n", "")


def stats_row(output: str, name: str) -> list[str]:
    """A row of ``cache stats``' table, its cells."""
    line = next(line for line in output.splitlines() if line.strip("│ ").startswith(name + " "))
    return [cell.strip() for cell in line.strip().strip("│").split("│")]


def test_verdicts_and_kept_photos_are_known_to_the_store_s_housekeeping(tmp_path: Path) -> None:
    assert "verdicts" in TABLES
    spec = make_run(tmp_path)
    store = Store(tmp_path / "store")
    kept = {}
    for job in (0, 1):  # what realism score keeps: the framed photograph, named by its file's SHA-256
        sha = f"{job:064x}"
        photo_path(store, sha).parent.mkdir(parents=True, exist_ok=True)
        photo_path(store, sha).write_bytes(photo_like(image_of((200, 10, 10)), seed=job))
        kept[job] = sha
    rows = [{**verdict(job, True), "photo": f"{job}.jpg", "photo_sha256": kept[job]} for job in (0, 1)]
    store.append(VERDICTS, [{**rows[0], "correct": False, "created_at": T1 - timedelta(days=1)}], VERDICT_SCHEMA)
    store.append(VERDICTS, rows, VERDICT_SCHEMA)  # job 0 scored again: its newer verdict counts
    orphan = photo_path(store, "f" * 64)  # a kept photo of a verdict no longer stored
    orphan.write_bytes(photo_path(store, kept[0]).read_bytes())
    mine = orphan.parent / "notes.txt"  # the user's own file: never the store's to remove
    mine.write_text("lens 28 mm")
    stale = orphan.parent / ".gone.jpg.abc.tmp"  # a killed scorer's temp file, an hour old
    stale.write_bytes(b"x")
    os.utime(stale, (time.time() - 7200, time.time() - 7200))

    code, out = cache(spec, "stats")
    assert code == 0, out
    assert stats_row(out, "verdicts")[1:4] == ["2", "3", "2"]  # files, rows, keys (job 0 twice)
    assert stats_row(out, "kept photos")[1:4] == ["4", "4", "2"]  # 4 files, 2 of them named by a verdict
    code, out = cache(spec, "verify")
    assert code == 0 and "2 kept photos" in flat(out) and "store OK" in flat(out), out

    code, out = cache(spec, "compact")
    assert code == 0 and "verdicts: 2 segments → 1 (3 rows → 2)" in flat(out), out
    merged = store.table(VERDICTS).to_pylist()
    assert sorted((r["job"], r["correct"]) for r in merged) == [(0, True), (1, True)]  # the newest of job 0

    code, out = cache(spec, "gc")
    assert code == 0 and "1 kept photos no verdict names" in flat(out), out
    assert not orphan.exists() and not stale.exists() and mine.exists()
    assert all(photo_path(store, sha).exists() for sha in kept.values())

    photo_path(store, kept[1]).write_bytes(b"\xff\xd8 not a whole JPEG")
    code, out = cache(spec, "verify")
    assert code == 2 and f"corrupt kept photo: realism/photos/{kept[1]}.jpg" in flat(out), out
    code, out = cache(spec, "verify", "--repair")
    assert code == 0 and "repaired 1 problems" in flat(out), out
    assert not photo_path(store, kept[1]).exists() and (store.root / "quarantine").is_dir()
    code, out = cache(spec, "verify")  # the photo itself is gone: scoring again keeps it anew
    assert code == 2 and f"missing kept photo: realism/photos/{kept[1]}.jpg" in flat(out), out


def test_the_verdicts_contract_is_realism_s_and_matches_the_rows_it_writes() -> None:
    """Scoring again writes a newer row of the same key: the newest counts; the photos a verdict
    names are the table's kept files, under the folder the report reads them from."""
    from sweep3d.cache import contract_of
    from sweep3d.results import PHOTOS_FOLDER

    contract = contract_of(VERDICTS)
    assert contract.key == "verdict_key" and contract.merge == "newest"
    assert set(contract.columns) <= set(VERDICT_SCHEMA.names)
    assert contract.kept is not None and contract.kept.folder == PHOTOS_FOLDER
    assert contract.kept.column in VERDICT_SCHEMA.names
    assert contract.kept.path(Path("/s"), "ab") == photo_path(Store(Path("/s")), "ab")

