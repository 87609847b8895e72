"""Silent wrong answers in the store (issue 35, item 10): a kept model output edited in place, a
mesh extracted under ``assets/`` edited in place, and a table segment rewritten without a column
and without its list of columns. Each was used as if intact, and ``cache verify`` said OK; each is
now found by the next run (refused or rebuilt, with a warning) and by ``cache verify``, and repaired.

Edits go through the same file with its size and mtime set back, as an editor that restores them
would: only the change time, which no one can set back, and the bytes tell them apart. The stores
here are synthetic (fast); the end-to-end runs are at the bottom (a real tiny run each).
"""

from __future__ import annotations

import io
import logging
import os
import shutil
import zipfile
from pathlib import Path
from typing import Callable

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from sweep3d.assets.sources import materialise_mesh
from sweep3d.cache.blobs import sha256_bytes
from sweep3d.cache.digested import TRAILER
from sweep3d.cache.maintenance import compact_table, repair, verify
from sweep3d.cache.store import DIGEST_COLUMN, Store, atomic_write, segment_name
from sweep3d.cli import app
from sweep3d.core.evaluation import EVALUATOR_METADATA, EvaluatorRecord, Roles
from sweep3d.core.pixels import encode_png
from sweep3d.results import connect as connect_results
from sweep3d.runner.pipeline import run
from sweep3d.stages.infer.kept_outputs import KeptOutputs
from tests.helpers import CUBE_OBJ, T0, TINY_SPEC, load_spec, plan_for, render_row, write_spec


def edit_in_place(path: Path, change: Callable[[bytes], bytes]) -> None:
    """Rewrite ``path``'s bytes through the same inode, then set its times back: the same size,
    the same mtime (only the change time moves)."""
    st = path.stat()
    data = change(path.read_bytes())
    assert len(data) == st.st_size
    with open(path, "r+b") as fh:
        fh.write(data)
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert path.stat().st_mtime_ns == st.st_mtime_ns and path.stat().st_size == st.st_size


def another_winner(data: bytes) -> bytes:
    """A kept output whose array was changed (another class wins), its recorded digest left as it was."""
    body = data[:-TRAILER]
    buffer = io.BytesIO()
    np.save(buffer, np.roll(np.load(io.BytesIO(body)), 1), allow_pickle=False)
    assert len(buffer.getvalue()) == len(body)
    return buffer.getvalue() + data[-TRAILER:]


def store_warnings(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "sweep3d.store" and r.levelno >= logging.WARNING]


# -- (a) kept model outputs ------------------------------------------------------------------------
LOGITS = np.array([[0.1, 3.0, 0.2, 0.3], [2.0, 0.1, 0.1, 0.1], [0.1, 0.1, 0.1, 4.0]], np.float32)


def test_a_kept_output_edited_in_place_is_refused_with_a_warning_and_kept_anew(tmp_path: Path, caplog) -> None:
    kept = KeptOutputs(Store(tmp_path / "store"), "model", "torch", "classification")
    kept.save(["a", "b", "c"], LOGITS)
    kept.close()  # its files written
    edit_in_place(kept._path("b"), another_winner)
    assert np.argmax(np.load(kept._path("b"))) != np.argmax(LOGITS[1]), "the edit would change the prediction"

    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        assert kept.load(["a", "b"]) is None, "the model runs for the batch"
        assert np.array_equal(kept.load(["a", "c"]), LOGITS[[0, 2]]), "intact outputs are still used"
    [warning] = store_warnings(caplog)
    assert "1 kept model output (outputs/" in warning and "does not match the digest" in warning, warning
    kept.save(["a", "b"], LOGITS[:2])  # what the infer stage does with the model's answers
    assert np.array_equal(kept.load(["a", "b"]), LOGITS[:2])


def test_a_kept_output_without_a_digest_is_never_used(tmp_path: Path, caplog) -> None:
    """Written before digests were kept, or saved over by another tool: the model runs again."""
    kept = KeptOutputs(Store(tmp_path / "store"), "model", "torch", "classification")
    kept.save(["a"], LOGITS[:1])
    kept.close()
    np.save(kept._path("a"), LOGITS[2])
    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        assert kept.load(["a"]) is None
    assert len(store_warnings(caplog)) == 1


def test_verify_finds_an_edited_kept_output_and_repair_quarantines_it(tmp_path: Path) -> None:
    root = tmp_path / "store"
    kept = KeptOutputs(Store(root), "model", "torch", "classification")
    kept.save(["a", "b"], LOGITS[:2])
    kept.close()
    assert verify(root).ok and verify(root).outputs == 2
    edit_in_place(kept._path("a"), another_winner)

    report = verify(root)
    assert [(p.kind, p.path) for p in report.problems] == [("corrupt kept output", kept._path("a"))]
    assert "does not match the SHA-256" in report.problems[0].detail
    with Store(root).lock():
        assert repair(root, report) == 1
    assert not kept._path("a").exists() and list((root / "quarantine").rglob(kept._path("a").name))
    assert verify(root).ok and kept.load(["a"]) is None  # the model answers again


# -- (b) meshes extracted from an archive ----------------------------------------------------------
def archive_spec(folder: Path, obj: str = CUBE_OBJ) -> Path:
    """The tiny spec with its cube inside a zip (``box.zip#box/box.obj``, beside a texture)."""
    with zipfile.ZipFile(folder / "box.zip", "w") as zf:
        zf.writestr("box/box.obj", obj)
        zf.writestr("box/notes.txt", "not a mesh")
    return write_spec(folder, TINY_SPEC.replace('mesh = "cube.obj"', 'mesh = "box.zip#box/box.obj"'), cube=False)


def render_keys(spec: Path) -> list[str]:
    return [j.render_key for j in plan_for(load_spec(spec), "0" * 64).jobs]


def test_an_extracted_mesh_edited_in_place_is_extracted_again_before_use(tmp_path: Path, caplog) -> None:
    spec = archive_spec(tmp_path)
    keys = render_keys(spec)
    [copy] = (tmp_path / "store" / "assets").iterdir()
    obj = copy / "box" / "box.obj"
    edit_in_place(obj, lambda data: data.replace(b"v 1 1 1", b"v 9 1 1"))  # another object

    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        assert render_keys(spec) == keys, "keys follow the archive ..."
    assert obj.read_text() == CUBE_OBJ, "... and so does what renders"
    [warning] = store_warnings(caplog)
    assert f"box.zip#box/box.obj extracted under the store's assets/{copy.name} was changed since" in warning
    assert "box/box.obj does not match what was extracted" in warning and "extracting it again" in warning
    caplog.clear()
    materialise_mesh(load_spec(spec).meshes["box"], tmp_path / "store")  # what the render stage does
    assert not store_warnings(caplog)


def test_a_touched_but_intact_copy_is_hashed_once_and_not_extracted_again(tmp_path: Path) -> None:
    spec = archive_spec(tmp_path)
    render_keys(spec)
    [copy] = (tmp_path / "store" / "assets").iterdir()
    obj = copy / "box" / "box.obj"
    edit_in_place(obj, lambda data: data)  # rewritten with the same bytes: the change time moves
    inode = obj.stat().st_ino
    before = (copy / ".complete").read_bytes()
    render_keys(spec)
    assert obj.stat().st_ino == inode and (copy / ".complete").read_bytes() != before, "its new state remembered"


def test_a_new_archive_at_the_same_path_is_extracted_without_a_warning(tmp_path: Path, caplog) -> None:
    spec = archive_spec(tmp_path)
    keys = render_keys(spec)
    archive_spec(tmp_path, CUBE_OBJ.replace("v 1 1 1", "v 2 1 1"))
    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        assert set(render_keys(spec)).isdisjoint(keys)
    assert not store_warnings(caplog)
    [copy] = (tmp_path / "store" / "assets").iterdir()
    assert "v 2 1 1" in (copy / "box" / "box.obj").read_text()


def test_verify_finds_an_edited_extracted_mesh_and_repair_sets_it_aside(tmp_path: Path) -> None:
    spec = archive_spec(tmp_path)
    keys = render_keys(spec)
    root = tmp_path / "store"
    [copy] = (root / "assets").iterdir()
    assert verify(root).ok and verify(root).assets == 1
    edit_in_place(copy / "box" / "box.obj", lambda data: data.replace(b"v 1 1 1", b"v 9 1 1"))

    report = verify(root)
    assert [(p.kind, p.path) for p in report.problems] == [("corrupt extracted asset", copy / "box" / "box.obj")]
    assert "does not match the SHA-256 recorded when it was extracted" in report.problems[0].detail
    with Store(root).lock():
        assert repair(root, report) == 1
    assert not copy.exists() and (root / "quarantine" / "assets" / copy.name / "box" / "box.obj").exists()
    assert render_keys(spec) == keys and verify(root).ok


def test_an_extraction_from_before_manifests_is_extracted_again_silently(tmp_path: Path, caplog) -> None:
    spec = archive_spec(tmp_path)
    keys = render_keys(spec)
    [copy] = (tmp_path / "store" / "assets").iterdir()
    (copy / ".complete").write_text("ok")  # what extractions wrote before
    assert verify(tmp_path / "store").ok  # nothing recorded to check it against
    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        assert render_keys(spec) == keys
    assert not store_warnings(caplog) and (copy / ".complete").read_text().startswith("{")


# -- (c) a segment rewritten without a column and without its list of columns -------------------------
def unlisted(store: Store, table: str, rows: list[dict]) -> Path:
    """A segment of ``rows`` written as a tool would: no list of its columns in its metadata."""
    path = store.table_dir(table) / segment_name()
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.Table.from_pylist(rows), path)
    return path


def rendered(store: Store, key: str, digest: bool = True) -> dict:
    """A render's blob, and its row (with the blob's digest, unless ``digest`` is False: an old row)."""
    data = encode_png(np.full((4, 4, 3), 0.5, np.float32))
    atomic_write(store.blob_path(key), data)
    return render_row(key, 0, sha256_bytes(data) if digest else None)


def prediction(key: str, **columns) -> dict:
    return {"pred_key": key, "image_key": key, "model": "m", "model_digest": "d", "seconds": 0.1, "created_at": T0,
            **columns}


def test_a_segment_lacking_a_column_of_its_table_and_its_list_is_damaged(tmp_path: Path, caplog) -> None:
    """A renders segment rewritten without ``valid``, its metadata gone with it: its rows would read
    as renders of unknown validity. Verify names it; a run's read quarantines it."""
    root = tmp_path / "store"
    store = Store(root)
    damaged = store.append("renders", [rendered(store, f"{i}a" * 20) for i in range(3)])
    kept = store.append("renders", [rendered(store, "ff" * 20)])
    pq.write_table(pq.read_table(damaged).drop_columns(["valid"]).replace_schema_metadata(None), damaged)

    problems = verify(root).problems
    assert [(p.kind, p.path) for p in problems] == [("corrupt segment", damaged)]
    assert "lacks the column 'valid' that every renders row has, and lists no columns of its own" in problems[0].detail
    reader = Store(root)
    with reader.lock():
        assert reader.keys("renders") == {"ff" * 20}
    assert not damaged.exists() and kept.exists() and verify(root).ok
    assert any("moved it to quarantine/" in w for w in store_warnings(caplog))


def test_a_legacy_segment_with_its_tables_columns_is_read_as_it_was(tmp_path: Path) -> None:
    """Segments written before they listed their columns (or stripped of the list) hold every
    column their table's rows always had: they read, and verify passes them."""
    store = Store(tmp_path / "store")
    row = {k: v for k, v in rendered(store, "aa" * 20, digest=False).items() if k != DIGEST_COLUMN}  # before digests
    unlisted(store, "renders", [row])
    unlisted(store, "predictions", [prediction("p", valid=True, correct=True, top1_label="carton")])
    assert Store(store.root).keys("renders") == {"aa" * 20} and Store(store.root).keys("predictions") == {"p"}
    assert verify(store.root).ok


def test_require_columns_judges_the_unlisted_segments_of_the_keys_only(tmp_path: Path, caplog) -> None:
    """A predictions segment of this evaluator's keys without ``top1_label`` is damaged; one of
    another evaluator's keys (rightly without it) and one that lists its columns are not."""
    store = Store(tmp_path / "store")
    mine = unlisted(store, "predictions", [prediction("a1", valid=True, correct=True),
                                           prediction("a2", valid=True, correct=False)])
    theirs = unlisted(store, "predictions", [prediction("b1", valid=True, correct=True)])
    listed = store.append("predictions", [prediction("a3", valid=True, correct=True)])
    whose = "every row of the classification evaluator has"
    with store.lock():
        assert store.require_columns("predictions", ["pred_key", "top1_label"], {"a1", "a2", "a3"}, whose) == [mine]
        assert store.keys("predictions") == {"b1", "a3"}
    assert not mine.exists() and theirs.exists() and listed.exists()
    [warning] = store_warnings(caplog)
    assert f"{mine.name} is unreadable (it lacks the column 'top1_label' that {whose}" in warning


def _jobs(store: Store, keys: list[str], columns: tuple[str, ...]) -> None:
    """A plan's jobs file recording its evaluator (the classification one's ``columns``)."""
    record = EvaluatorRecord("classification", columns, Roles(prediction="top1_label"))
    table = pa.table({"job": list(range(len(keys))), "pred_key": keys})
    store.write_table_file(store.jobs_path("x"), table.replace_schema_metadata({EVALUATOR_METADATA: record.to_json()}))


def test_verify_judges_predictions_by_the_evaluator_their_plan_records(tmp_path: Path) -> None:
    """The issue's case: a predictions segment rewritten without ``top1_label`` and without its
    metadata read as NULL labels, and verify said OK. The plan's record of its evaluator names
    the column: verify reports the segment, repair sets it aside, compaction never merges it."""
    root = tmp_path / "store"
    store = Store(root)
    damaged = store.append("predictions", [prediction(f"k{i}", valid=True, correct=True, top1_label="carton")
                                           for i in range(3)])
    good = store.append("predictions", [prediction("k3", valid=True, correct=True, top1_label="carton")])
    store.append("predictions", [prediction("k4", valid=True, correct=False, top1_label="drum")])
    pq.write_table(pq.read_table(damaged).drop_columns(["top1_label"]).replace_schema_metadata(None), damaged)
    _jobs(store, ["k0", "k1", "k2", "k3", "k4"], ("valid", "correct", "top1_label"))

    report = verify(root)
    assert [(p.kind, p.path) for p in report.problems] == [("corrupt segment", damaged)]
    assert "'top1_label' that every row of the classification evaluator has" in report.problems[0].detail
    kept = tmp_path / "kept"
    shutil.copytree(root, kept)
    with Store(root).lock():
        assert repair(root, report) == 1
    assert verify(root).ok and Store(root).keys("predictions") == {"k3", "k4"} and good.exists()

    copy = Store(kept)
    with copy.lock():
        merged = compact_table(copy, "predictions")
    assert merged is not None and merged.rows_after == 2, "the damaged segment is not merged into NULLs"
    assert verify(kept).ok


# -- the next run finds each, and repairs it (real tiny runs) -------------------------------------------
def labels(folder: Path) -> dict[int, str]:
    """Each job's predicted top-1 label in the tiny run's results."""
    con = connect_results(Store(folder / "store"), "tiny")
    return dict(con.execute("SELECT job, top1_label FROM results ORDER BY job").fetchall())


def verify_cli(folder: Path) -> tuple[int, str]:
    result = CliRunner().invoke(app, ["cache", "verify", str(folder / "spec.toml")])
    return result.exit_code, " ".join(result.output.split())


def test_a_run_refuses_edited_kept_outputs_and_predicts_what_the_model_does(tiny_copy: Path, caplog) -> None:
    """The model's logits kept under ``outputs/`` edited in place (another class wins, mtime set
    back); a changed evaluator then re-evaluated from them and the jobs' predictions changed."""
    want = labels(tiny_copy)
    kept = sorted((tiny_copy / "store" / "outputs").rglob("*.npy"))
    assert len(kept) == 8
    for path in kept:
        edit_in_place(path, another_winner)
    code, output = verify_cli(tiny_copy)
    assert code == 2 and output.count("corrupt kept output: outputs/") == 8, output

    spec = tiny_copy / "spec.toml"
    spec.write_text(spec.read_text() + "\n[evaluator]\ntop_k = 3\n")  # new prediction keys: re-evaluated
    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        result = run(load_spec(spec))
    assert result.failed == 0 and result.outcome("infer").computed == 8
    assert any("kept model outputs" in w and "do not match the digest" in w for w in store_warnings(caplog))
    assert labels(tiny_copy) == want, "the model's answers, not the edited ones"
    assert verify_cli(tiny_copy)[0] == 0, "kept anew"


def test_a_run_finds_a_segment_rewritten_without_an_evaluator_column_and_recomputes_it(tiny_copy: Path,
                                                                                     caplog) -> None:
    """The predictions segments rewritten without ``top1_label`` and without their list of columns:
    verify and run once took the rows for NULL labels."""
    want = labels(tiny_copy)
    store = Store(tiny_copy / "store")
    for path in store.segments("predictions"):
        pq.write_table(pq.read_table(path).drop_columns(["top1_label"]).replace_schema_metadata(None), path)
    code, output = verify_cli(tiny_copy)
    assert code == 2 and "corrupt segment: tables/predictions/" in output
    assert "'top1_label' that every row of the classification evaluator has" in output

    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        result = run(load_spec(tiny_copy / "spec.toml"))
    assert result.failed == 0 and result.outcome("infer").computed == 8
    assert result.outcome("render").computed == 0 and result.outcome("postprocess").computed == 0
    assert any("moved it to quarantine/" in w and "top1_label" in w for w in store_warnings(caplog))
    assert labels(tiny_copy) == want
    assert verify_cli(tiny_copy)[0] == 0


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.torch
def test_a_run_renders_the_archives_mesh_not_an_edited_copy(tmp_path: Path, caplog) -> None:
    """A run extracts the cube from its zip and renders it; the copy is edited in place; the next
    run, asked for one more view, says so, extracts it again and renders the new job from the
    archive's mesh, its earlier renders cached (their keys are the archive's)."""
    spec = archive_spec(tmp_path)
    one = '[[environments]]\nname = "studio"\nhdri = "builtin:studio"\n\n'
    spec.write_text(spec.read_text().replace(one, "").replace("yaw = [0, 45]", "yaw = [0]")
                    .replace("sigma = [0.0, 1.5]", "sigma = [0.0]"))
    assert run(load_spec(spec)).failed == 0
    [copy] = (tmp_path / "store" / "assets").iterdir()
    edit_in_place(copy / "box" / "box.obj", lambda data: data.replace(b"v 1 1 1", b"v 9 1 1"))
    code, output = verify_cli(tmp_path)
    assert code == 2 and f"corrupt extracted asset: assets/{copy.name}/box/box.obj" in output, output

    spec.write_text(spec.read_text().replace("yaw = [0]", "yaw = [0, 45]"))
    with caplog.at_level(logging.WARNING, logger="sweep3d.store"):
        result = run(load_spec(spec))
    assert result.failed == 0
    assert (result.outcome("render").cached, result.outcome("render").computed) == (1, 1)
    assert any("was changed since" in w and "extracting it again" in w for w in store_warnings(caplog))
    assert (copy / "box" / "box.obj").read_text() == CUBE_OBJ
    assert verify_cli(tmp_path)[0] == 0
