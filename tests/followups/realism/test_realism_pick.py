"""``sweep3d realism pick``: half right and half wrong per object and model, seeded, spread over
environments and values, near ties left out, and a kit whose ``design.csv`` the table policy reads.

The store is synthetic (written row by row, with real PNG blobs): each job's image is a flat
colour whose red and blue means decide what the test model (``realism_model:redblue``, written
beside the spec) answers, so the verdicts stored here are the ones that model gives on them
(tests/followups/realism/test_realism_score.py runs it). The kit's edge images and alignment page come from
``sweep3d.followups.realism.edges`` and ``sweep3d.followups.realism.align``; the tests stand small stubs in for them
(:func:`stub_kit_tools`), so only what ``pick`` writes itself is checked here.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from PIL import Image

from sweep3d.cache.store import Store
from sweep3d.followups.realism.pick import margin, near_tie
from tests.helpers.realism import (
    LABELS,
    SIDE,
    image_of,
    job_colours,
    kit_files,
    make_run,
    pick,
    redblue_row,
    stub_kit_tools,
)


def test_margin_is_the_true_class_less_the_best_other() -> None:
    right = {"correct": True, "topk": [3, 1, 4], "topk_probs": [0.6, 0.3, 0.1], "label_prob": 0.6, "label_ids": [3]}
    wrong = {"correct": False, "topk": [1, 3], "topk_probs": [0.52, 0.47], "label_prob": 0.47, "label_ids": [3]}
    two_true = {"correct": True, "topk": [3, 4, 1], "topk_probs": [0.5, 0.3, 0.2], "label_prob": 0.8,
                "label_ids": [3, 4]}
    assert margin(right) == pytest.approx(0.3)
    assert margin(wrong) == pytest.approx(-0.05) and not near_tie(wrong)
    assert near_tie({**wrong, "topk_probs": [0.5, 0.47], "label_prob": 0.47})
    assert margin(two_true) == pytest.approx(0.6)  # the label set's probability against class 1
    assert margin({**right, "margin": -0.01}) == -0.01  # a stored margin column wins
    assert margin({"correct": True}) is None and not near_tie({"correct": True})


def test_pick_writes_a_deterministic_kit_half_right_half_wrong(tmp_path: Path, monkeypatch) -> None:
    spec = make_run(tmp_path)
    calls = stub_kit_tools(monkeypatch)
    result = pick(spec, tmp_path / "kit", "--per-object", "4")
    assert result.exit_code == 0, result.output
    kit = json.loads((tmp_path / "kit" / "kit.json").read_text())
    store = Store(tmp_path / "store")
    jobs = job_colours()
    for obj in LABELS:
        mine = [p for p in kit["picks"] if p["object"] == obj]
        assert sorted(p["correct"] for p in mine) == [False, False, True, True]
        for p in mine:  # the verdict the kit records is the store's
            assert p["correct"] == redblue_row(image_of(jobs[p["job"]]["rgb"]), LABELS[obj])["correct"]
        assert len({p["environment"] for p in mine}) == 2  # spread: both environments
        assert len({jobs[p["job"]]["orientation_yaw"] for p in mine}) == 3  # and every yaw
    assert kit["jobs"] == sorted({p["job"] for p in kit["picks"]})
    for job in kit["jobs"]:  # the raw render, byte for byte (no 2D controls here: the image the model saw); edges beside it
        key = f"{job:04x}" + "ab" * 30
        assert (tmp_path / "kit" / "renders" / f"{job}.png").read_bytes() == store.blob_path(key).read_bytes()
        with Image.open(tmp_path / "kit" / "edges" / f"{job}.png") as im:
            assert im.mode == "RGBA" and im.size == (SIDE, SIDE)
    assert [s.job_id for s in calls[0]] == [str(j) for j in kit["jobs"]]
    assert all(s.render == f"renders/{s.job_id}.png" and s.edges == f"edges/{s.job_id}.png" for s in calls[0])
    with (tmp_path / "kit" / "design.csv").open() as handle:
        design = list(csv.DictReader(handle))
    assert [(r["object"], r["environment"], float(r["orientation_yaw"])) for r in design] == [
        (jobs[j]["object"], jobs[j]["environment"], float(jobs[j]["orientation_yaw"])) for j in kit["jobs"]]

    again = pick(spec, tmp_path / "again", "--per-object", "4")
    assert again.exit_code == 0, again.output
    assert kit_files(tmp_path / "kit") == kit_files(tmp_path / "again")  # same seed: the same bytes
    photo = tmp_path / "kit" / f"{kit['jobs'][0]}.jpg"
    photo.write_bytes(b"a photograph")
    before = kit_files(tmp_path / "kit")
    assert pick(spec, tmp_path / "kit", "--per-object", "4").exit_code == 0  # picked again into the kit
    assert kit_files(tmp_path / "kit") == before and photo.read_bytes() == b"a photograph"
    other = pick(spec, tmp_path / "other", "--per-object", "4", "--seed", "11")
    assert other.exit_code == 0, other.output
    assert json.loads((tmp_path / "other" / "kit.json").read_text())["jobs"] != kit["jobs"]


def test_the_design_replays_with_the_table_policy(tmp_path: Path, monkeypatch) -> None:
    from sweep3d.stages.plan.design import read_design
    from tests.helpers import load_spec

    spec = make_run(tmp_path)
    stub_kit_tools(monkeypatch)
    assert pick(spec, tmp_path / "kit", "--per-object", "2").exit_code == 0
    replay = tmp_path / "replay.toml"
    replay.write_text(spec.read_text().replace('type = "grid"', 'type = "table"\nfile = "kit/design.csv"'))
    loaded = load_spec(replay)  # the table policy binds the file: every cell checked against the spec
    scenes = read_design(tmp_path / "kit" / "design.csv", loaded.controls, [o.name for o in loaded.objects],
                         [e.name for e in loaded.environments], tmp_path)
    assert sum(s.count for s in scenes.values()) == len(json.loads((tmp_path / "kit" / "kit.json").read_text())["jobs"])


def test_near_ties_are_left_out_or_marked(tmp_path: Path, monkeypatch) -> None:
    jobs = job_colours()
    rows = [redblue_row(image_of(j["rgb"]), LABELS[j["object"]]) for j in jobs]
    tied = set(range(0, len(jobs), 2))  # every other job a near tie: p(true) and p(other) 0.02 apart
    for i in tied:
        truth, other = (0.51, 0.49) if rows[i]["correct"] else (0.49, 0.51)
        rows[i] = {**rows[i], "topk_probs": [max(truth, other), min(truth, other)], "label_prob": truth}
    spec = make_run(tmp_path, jobs, rows)
    stub_kit_tools(monkeypatch)
    assert pick(spec, tmp_path / "left", "--per-object", "4").exit_code == 0
    left = json.loads((tmp_path / "left" / "kit.json").read_text())
    assert left["picks"] and not any(p["job"] in tied or p["near_tie"] for p in left["picks"])
    marked = pick(spec, tmp_path / "marked", "--per-object", "36", "--near-ties", "mark")
    assert marked.exit_code == 0, marked.output
    picks = json.loads((tmp_path / "marked" / "kit.json").read_text())["picks"]
    assert {p["job"] for p in picks if p["near_tie"]} == tied  # all jobs picked: the ties flagged
    assert all(abs(p["margin"]) < 0.05 for p in picks if p["near_tie"])


def test_a_folder_of_other_files_or_a_bad_option_is_one_line(tmp_path: Path, monkeypatch) -> None:
    spec = make_run(tmp_path)
    stub_kit_tools(monkeypatch)
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "notes.txt").write_text("mine")
    for args, words in (((str(tmp_path / "busy"),), "holds other files"),
                        ((str(tmp_path / "store" / "kit"),), "inside the store"),
                        ((str(tmp_path / "k"), "--per-object", "0"), "at least 1"),
                        ((str(tmp_path / "k"), "--near-ties", "keep"), "leave or mark")):
        result = pick(spec, Path(args[0]), *args[1:])
        assert result.exit_code == 2, result.output
        assert words in result.output and len(result.output.strip().splitlines()) == 1
    assert (tmp_path / "busy" / "notes.txt").read_text() == "mine" and not (tmp_path / "k").exists()


def test_the_kit_goes_to_the_store_by_default_not_beside_the_spec(tmp_path: Path, monkeypatch) -> None:
    """Beside the spec, a kit of renders lands in the user's repository; in the store's kits
    folder it does not, and ``-o`` may name it (elsewhere in the store stays refused)."""
    from typer.testing import CliRunner

    from sweep3d.cli import app

    spec = make_run(tmp_path)
    stub_kit_tools(monkeypatch)
    beside = set(tmp_path.iterdir())
    result = CliRunner().invoke(app, ["realism", "pick", str(spec), "--per-object", "2"])
    assert result.exit_code == 0, result.output
    kit = tmp_path / "store" / "kits" / "realism"
    assert (kit / "kit.json").is_file() and str(kit / "align.html") in result.output.replace("\n", "")
    assert set(tmp_path.iterdir()) == beside  # nothing new beside the spec
    again = pick(spec, kit, "--per-object", "2")  # the default, named outright: an earlier kit, replaced
    assert again.exit_code == 0, again.output
    result = pick(spec, tmp_path / "store" / "tables" / "kit")
    assert result.exit_code == 2 and "inside the store" in result.output and "kits" in result.output


def test_an_output_folder_the_user_may_not_read_is_one_line(monkeypatch) -> None:
    """Issue 45, item 8: ``-o`` a folder the user may not read was a four-line usage error (click's
    check that a path is readable). Run as a user the permissions hold for: one line, exit 2."""
    import shutil
    import tempfile

    from tests.helpers.users import as_user, hand_over

    folder = Path(tempfile.mkdtemp(prefix="sweep3d-pick-")) / "run"
    try:
        folder.mkdir()
        spec = make_run(folder)
        stub_kit_tools(monkeypatch)
        assert pick(spec, folder / "warm").exit_code == 0  # what the unprivileged child runs is imported here
        denied = folder / "denied"
        denied.mkdir()
        (denied / "photo.jpg").write_text("a user's photograph")
        hand_over(folder)
        denied.chmod(0)
        code, output = as_user(lambda: (lambda r: (r.exit_code, r.output))(pick(spec, denied)))
        denied.chmod(0o755)
        assert code == 2, output
        assert output.strip() == (f"error: -o {denied}: cannot be read (Permission denied); fix its permissions or "
                                  "choose another folder for the kit"), output
        assert [p.name for p in denied.iterdir()] == ["photo.jpg"]
    finally:
        shutil.rmtree(folder.parent)


def test_a_full_disk_while_writing_the_kit_is_one_line_and_leaves_nothing(tmp_path: Path, monkeypatch) -> None:
    import errno

    spec = make_run(tmp_path)
    stub_kit_tools(monkeypatch)

    def full(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "write_bytes", full)
    result = pick(spec, tmp_path / "kit")
    assert result.exit_code == 2, result.output
    assert result.output.strip() == (f"error: {tmp_path / 'kit'}: cannot write the kit (No space left on device); "
                                     "free some disk space, or write the kit to another disk with -o"), result.output
    assert not (tmp_path / "kit").exists() and not list(tmp_path.glob(".kit.*"))


def test_a_missing_or_damaged_render_is_one_line_and_writes_no_kit(tmp_path: Path, monkeypatch) -> None:
    """The kit copies each picked job's raw render, checked against the digest its ``renders`` row
    recorded: a blob gone or changed since is one line naming it and the fix, and no kit."""
    from datetime import datetime, timezone

    from sweep3d.cache.blobs import sha256_bytes

    spec = make_run(tmp_path)
    stub_kit_tools(monkeypatch)
    store = Store(tmp_path / "store")
    keys = [r["image_key"] for r in store.table("images").to_pylist()]  # make_run: each render is its image
    store.append("renders", [{"render_key": k, "width": SIDE, "height": SIDE, "valid": True, "seconds": 0.1,
                              "created_at": datetime(2024, 1, 1, tzinfo=timezone.utc),
                              "sha256": sha256_bytes(store.blob_path(k).read_bytes())} for k in keys])
    assert pick(spec, tmp_path / "fine").exit_code == 0  # recorded digests that hold
    for key in keys:
        store.blob_path(key).write_bytes(store.blob_path(key).read_bytes() + b"changed")
    damaged = pick(spec, tmp_path / "kit")
    assert damaged.exit_code == 2 and len(damaged.output.strip().splitlines()) == 1, damaged.output
    assert "no longer matches its recorded digest" in damaged.output and f"sweep3d run {spec}" in damaged.output
    for key in keys:
        store.blob_path(key).unlink()
    missing = pick(spec, tmp_path / "kit")
    assert missing.exit_code == 2 and len(missing.output.strip().splitlines()) == 1, missing.output
    assert "is missing" in missing.output and "then pick" in missing.output
    assert not (tmp_path / "kit").exists() and not list(tmp_path.glob(".kit.*"))
