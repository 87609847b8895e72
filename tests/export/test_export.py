"""``sweep3d export``: a run's results as COCO, ImageFolder or Parquet, with ``design.csv``.

One tiny real run (a detection evaluator with the mask pass, 40 px, a fixed-box detector so
that some jobs fail, two objects, a control that applies to one of them, and jobs too little
visible to be evaluable) is shared by the end-to-end tests; the checks of bad input and the
COCO pitfalls that need a non-square image run on synthetic files, in the fast lane.
"""

from __future__ import annotations

import csv
import filecmp
import hashlib
import io
import json
import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from PIL import Image
from typer.testing import CliRunner

from sweep3d.cache.blobs import load_pass
from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.core.errors import UserError
from sweep3d.driver.progress import StageProgress
from sweep3d.export.coco import CocoWriter
from sweep3d.export.formats import Batch, Item
from sweep3d.export.parquet import ParquetWriter
from sweep3d.export.selection import IMAGE_DIGEST, MASK_DIGEST, check_where
from sweep3d.export.target import ExportFolder, Staging, class_folder, design_table
from sweep3d.results import connect
from sweep3d.results.views import stored_parameters
from tests.helpers import TINY_SPEC, spec_toml, write_spec

SPEC = spec_toml("export",
        seed=2,
        render={"resolution": 40, "samples": 1, "denoise": False},
        objects=("box", "crate"),
        body="""\
[model]
name = "export_detector:centre"

[evaluator]
kind = "detection"
passes = ["mask"]

[[controls]]
type = "orientation"
yaw = [0, 45]

[[controls]]
type = "position"
x = [0.0, 1.6]                 # 1.6: a sliver of the object in frame, not evaluable

[[controls]]
type = "scale"
factor = [1.0, 0.6]
objects = ["crate"]            # no scale_factor for the box: an empty cell in design.csv

[policy]
type = "grid"
""")

#: Always one box in the image's centre, labelled carton: right on a centred box, wrong on the crate.
DETECTOR = '''
import torch
from sweep3d.stages.infer import Detector


class Centre(torch.nn.Module):
    def forward(self, images):
        out = []
        for image in images:
            h, w = image.shape[-2:]
            box = torch.tensor([[w * 0.25, h * 0.25, w * 0.75, h * 0.75]], dtype=torch.float32)
            out.append({"boxes": box, "labels": torch.tensor([1]), "scores": torch.tensor([0.9])})
        return out


def centre():
    return Detector(Centre(), labels=["background", "carton", "crate"])
'''
LABELS = {"box": "carton", "crate": "crate"}


@pytest.fixture(scope="module")
def export_run(tmp_path_factory) -> Path:
    """A folder with the spec and its store after one real run (10 results: 2 jobs are out of frame)."""
    folder = tmp_path_factory.mktemp("export_run")
    (folder / "export_detector.py").write_text(DETECTOR)
    result = CliRunner().invoke(app, ["run", str(write_spec(folder, SPEC)), "--no-report"])
    assert result.exit_code == 0, result.output
    return folder


def export(folder: Path, *args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, ["export", str(folder / "spec.toml"), *args])
    return result.exit_code, result.output


def exported(folder: Path, out: Path, *args: str) -> Path:
    code, output = export(folder, "-o", str(out), *args)
    assert code == 0, output
    return out


def results(folder: Path, where: str = "true") -> dict[int, dict]:
    """``results`` rows by job."""
    cursor = connect(Store(folder / "store"), "export").execute(f"SELECT * FROM results WHERE {where} ORDER BY job")
    names = [d[0] for d in cursor.description]
    return {row[1]: dict(zip(names, row)) for row in cursor.fetchall()}


def hugging_face(monkeypatch):
    """``datasets``, told to stay offline (it reads its settings when first imported)."""
    monkeypatch.setenv("HF_DATASETS_OFFLINE", "1")
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    import datasets

    return datasets


def blob(folder: Path, key: str) -> bytes:
    return Store(folder / "store").blob_path(key).read_bytes()


def manifest(out: Path) -> dict:
    return json.loads((out / "sweep3d-export.json").read_text())


def tree(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


# -- COCO ----------------------------------------------------------------------------------------
def test_coco_round_trip_boxes_masks_areas_sizes_and_categories(export_run: Path, tmp_path: Path) -> None:
    from pycocotools.coco import COCO

    out = exported(export_run, tmp_path / "coco", "--format", "coco", "--where", "true", "--unevaluable", "flag")
    coco = COCO(str(out / "annotations.json"))
    rows = results(export_run)
    store = Store(export_run / "store")
    assert [c["id"] for c in coco.dataset["categories"]] == [1, 2]  # never 0, the background of many trainers
    names = {c["id"]: c["name"] for c in coco.dataset["categories"]}
    assert sorted(names.values()) == ["carton", "crate"]
    assert len(coco.getImgIds()) == len(rows) == 10
    for image in coco.dataset["images"]:
        attributes = image["attributes"]
        row = rows[attributes["job"]]
        data = (out / "images" / image["file_name"]).read_bytes()
        assert data == blob(export_run, row["image_key"])  # the stored image itself
        with Image.open(io.BytesIO(data)) as picture:
            assert (image["width"], image["height"]) == picture.size
        assert attributes["orientation_yaw"] == row["orientation_yaw"] and attributes["position_x"] == row["position_x"]
        assert attributes["scale_factor"] == row["scale_factor"] and attributes["evaluable"] == row["evaluable"]
        assert attributes["object"] == row["object"] and attributes["correct"] == row["correct"]
        annotations = coco.loadAnns(coco.getAnnIds(imgIds=[image["id"]]))
        mask = load_pass(store, row["truth_key"], "mask")
        if not mask.any():  # nothing of the object shows: no (zero-area) annotation
            assert annotations == [] and row["visible_pixels"] == 0
            continue
        (annotation,) = annotations
        assert names[annotation["category_id"]] == LABELS[row["object"]]
        assert type(annotation["area"]) is int and annotation["area"] == int(mask.sum()) == row["visible_pixels"]
        assert annotation["bbox"] == [row["gt_x0"], row["gt_y0"], row["gt_x1"] - row["gt_x0"],
                                      row["gt_y1"] - row["gt_y0"]]
        assert np.array_equal(coco.annToMask(annotation).astype(bool), mask)  # the mask pass, decoded
        assert annotation["iscrowd"] == 0 and annotation.get("ignore", 0) == (0 if row["evaluable"] else 1)
    shown = sum(1 for row in rows.values() if row["visible_pixels"])
    assert len({a["id"] for a in coco.dataset["annotations"]}) == len(coco.dataset["annotations"]) == shown >= 6


def test_an_oracle_from_the_exported_annotations_scores_ap_one(export_run: Path, tmp_path: Path) -> None:
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    out = exported(export_run, tmp_path / "coco", "--format", "coco", "--where", "true")
    truth = COCO(str(out / "annotations.json"))
    oracle = [{"image_id": a["image_id"], "category_id": a["category_id"], "bbox": a["bbox"],
               "segmentation": a["segmentation"], "score": 1.0} for a in truth.dataset["annotations"]]

    def average_precision(detections: list[dict], kind: str) -> float:
        evaluation = COCOeval(truth, truth.loadRes(detections), kind)
        evaluation.evaluate()
        evaluation.accumulate()
        evaluation.summarize()
        return float(evaluation.stats[0])

    assert average_precision(oracle, "bbox") == 1.0
    assert average_precision(oracle, "segm") == 1.0
    shifted = [{**d, "bbox": [d["bbox"][0] + d["bbox"][2], *d["bbox"][1:]]} for d in oracle]
    assert average_precision(shifted, "bbox") < 0.5  # the same boxes a width aside: the check can fail


def _png(width: int, height: int) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(np.zeros((height, width, 3), np.uint8)).save(buffer, format="PNG")
    return buffer.getvalue()


def test_coco_of_a_wide_image_keeps_width_and_height_and_skips_empty_masks(tmp_path: Path) -> None:
    """Width and height, the RLE's size and the box on a non-square image (the renderer makes square
    ones, where a swap would not show); an empty mask makes no annotation; an append continues ids."""
    from pycocotools.coco import COCO

    from sweep3d.core.truth import encode_mask

    store = Store(tmp_path / "store")
    mask = np.zeros((24, 40), bool)
    mask[3:9, 25:38] = True  # wide and to the right: a swap would put it out of the image
    items = []
    for i, m in enumerate((mask, np.zeros_like(mask))):
        image_key, truth_key = f"aa{i}", f"bb{i}"
        for key, ext, data in ((image_key, "png", _png(40, 24)), (truth_key, "mask.png", encode_mask(m))):
            store.blob_path(key, ext).parent.mkdir(parents=True, exist_ok=True)
            store.blob_path(key, ext).write_bytes(data)
        row = {"experiment": "e", "job": i, "image_key": image_key, "truth_key": truth_key,
               IMAGE_DIGEST: hashlib.sha256(_png(40, 24)).hexdigest(),
               MASK_DIGEST: hashlib.sha256(encode_mask(m)).hexdigest()}
        items.append(Item(i + 1, i, row, "carton", 1, {"job": i}))
    folder = ExportFolder(tmp_path / "out", "coco", fresh=True, categories={"carton": 1})
    staging = Staging(folder)
    CocoWriter().write(Batch(items, store, pa.table({}), []), folder, staging, StageProgress(None, None))
    staging.commit()
    coco = COCO(str(tmp_path / "out" / "annotations.json"))
    assert [(i["width"], i["height"]) for i in coco.dataset["images"]] == [(40, 24), (40, 24)]
    (annotation,) = coco.dataset["annotations"]  # the empty mask has none
    assert annotation["bbox"] == [25, 3, 13, 6] and annotation["area"] == 78
    assert annotation["segmentation"]["size"] == [24, 40]  # COCO's RLE size is (height, width)
    assert np.array_equal(coco.annToMask(annotation).astype(bool), mask)
    # appending continues image and annotation ids after the largest ones there
    appended = ExportFolder(tmp_path / "out", "coco", fresh=False, categories={"carton": 1})
    staging = Staging(appended)
    more = [Item(3, 0, items[0].row, "carton", 1, {"job": 0})]
    CocoWriter().write(Batch(more, store, pa.table({}), []), appended, staging, StageProgress(None, None))
    staging.commit()
    document = json.loads((tmp_path / "out" / "annotations.json").read_text())
    assert [i["id"] for i in document["images"]] == [1, 2, 3]
    assert [a["id"] for a in document["annotations"]] == [1, 2] and document["annotations"][1]["image_id"] == 3


# -- ImageFolder and Parquet --------------------------------------------------------------------
def test_imagefolder_loads_back_with_the_same_images_and_labels(export_run: Path, tmp_path: Path, monkeypatch) -> None:
    datasets = hugging_face(monkeypatch)

    out = exported(export_run, tmp_path / "folder", "--format", "imagefolder", "--where", "true", "--link")
    rows = results(export_run, "evaluable IS NOT FALSE")
    by_id = {entry["id"]: entry for entry in manifest(out)["items"]}
    files = sorted(p for p in out.rglob("*.png"))
    assert len(files) == len(rows) == 6 and {p.parent.name for p in files} == {"carton", "crate"}
    store = Store(export_run / "store")
    for path in files:  # as torchvision's ImageFolder reads it: the class is the folder
        row = rows[by_id[int(path.stem)]["job"]]
        assert path.parent.name == LABELS[row["object"]]
        assert path.read_bytes() == blob(export_run, row["image_key"])
        assert os.path.samefile(path, store.blob_path(row["image_key"]))  # --link: the blob itself
    loaded = datasets.load_dataset("imagefolder", data_dir=str(out), split="train", cache_dir=str(tmp_path / "hf"))
    assert len(loaded) == 6
    for record in loaded:
        row = rows[record["job"]]
        assert record["label"] == LABELS[row["object"]]
        stored = np.asarray(Image.open(io.BytesIO(blob(export_run, row["image_key"]))).convert("RGB"))
        assert np.array_equal(np.asarray(record["image"].convert("RGB")), stored)


def test_parquet_is_a_hugging_face_dataset_of_the_image_bytes_and_every_results_column(export_run: Path,
                                                                                       tmp_path: Path,
                                                                                       monkeypatch) -> None:
    datasets = hugging_face(monkeypatch)

    import sweep3d

    done = sweep3d.load(export_run / "spec.toml").export("parquet", tmp_path / "parquet", where="true",
                                                         unevaluable="flag")  # the Python API, as the CLI
    out = done.folder
    assert (done.added, done.total, done.left_out, done.already) == (10, 10, 0, 0)
    (path,) = (out / "data").glob("*.parquet")
    table = pq.read_table(path)
    assert table.schema.field("image").type == pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    rows = results(export_run)
    assert set(rows[0]) <= set(table.column_names)  # every column of results
    loaded = datasets.load_dataset(str(out), split="train", cache_dir=str(tmp_path / "hf"))
    assert isinstance(loaded.features["image"], datasets.Image) and len(loaded) == 10
    raw = loaded.cast_column("image", datasets.Image(decode=False))
    for record in raw:
        row = rows[record["job"]]
        assert record["image"]["bytes"] == blob(export_run, row["image_key"])  # byte-identical
        assert record["label"] == LABELS[row["object"]]
        assert all(record[c] == pytest.approx(v) if isinstance(v, float) else record[c] == v
                   for c, v in row.items() if not isinstance(v, list))
    assert list(raw["id"]) == list(range(1, 11)) and list(raw["job"]) == sorted(rows)


def test_appending_other_columns_to_parquet_rewrites_the_earlier_files_to_one_schema(tmp_path: Path) -> None:
    """An append from another experiment (other controls) keeps one schema over the files, which
    ``datasets`` needs: the earlier file gains the new columns as nulls."""
    store = Store(tmp_path / "store")
    data = _png(8, 8)
    store.blob_path("aa0").parent.mkdir(parents=True)
    store.blob_path("aa0").write_bytes(data)
    row = {"experiment": "e", "job": 0, "image_key": "aa0", IMAGE_DIGEST: hashlib.sha256(data).hexdigest()}
    batches = [pa.table({"job": [0], "yaw": [45.0]}), pa.table({"job": [0], "sigma": [2.0], "skin": ["zebra"]})]
    for n, table in enumerate(batches):
        folder = ExportFolder(tmp_path / "out", "parquet", fresh=n == 0)
        staging = Staging(folder)
        ParquetWriter().write(Batch([Item(n + 1, 0, row, "carton", 1, {})], store, table, table.column_names),
                              folder, staging, StageProgress(None, None))
        staging.commit()
    files = sorted((tmp_path / "out" / "data").glob("*.parquet"))
    schemas = [pq.read_schema(p) for p in files]
    assert len(files) == 2 and schemas[0] == schemas[1]
    assert schemas[0].names == ["image", "id", "label", "job", "yaw", "sigma", "skin"]
    both = pa.concat_tables(pq.read_table(p) for p in files)
    assert both.column("yaw").to_pylist() == [45.0, None] and both.column("skin").to_pylist() == [None, "zebra"]
    assert both.column("image").to_pylist()[1]["bytes"] == data


# -- the design table, the selection, ids ------------------------------------------------------
def test_the_default_exports_the_evaluable_failures_with_their_design_table(export_run: Path, tmp_path: Path) -> None:
    out = exported(export_run, tmp_path / "failures", "--format", "imagefolder")
    failures = results(export_run, "NOT correct AND evaluable IS NOT FALSE")
    assert [e["job"] for e in manifest(out)["items"]] == sorted(failures) and failures
    every = exported(export_run, tmp_path / "all", "--format", "imagefolder", "--where", "true", "--unevaluable", "flag")
    parameters = stored_parameters(Store(export_run / "store").jobs_path("export"))
    for folder, rows in ((out, failures), (every, results(export_run))):
        with open(folder / "design.csv", newline="") as fh:
            design = list(csv.reader(fh))
        assert design[0] == ["object", "environment", *parameters] == [
            "object", "environment", "orientation_yaw", "position_x", "scale_factor"]
        assert design[1:] == [["" if row[c] is None else str(row[c]) for c in design[0]] for row in rows.values()]
    boxes = [line for line in (every / "design.csv").read_text().splitlines() if line.startswith("box,")]
    assert len(boxes) == 4 and all(line.endswith(",") for line in boxes)  # no scale control on the box: empty


def test_the_design_table_replays_as_the_same_jobs_under_the_table_policy(export_run: Path, tmp_path: Path) -> None:
    """The loop closes: a spec whose ``table`` policy reads an export's ``design.csv`` plans the
    exported jobs again, in order, with the same keys (for a retrained model, say)."""
    from sweep3d.runner.pipeline import plan_spec
    from tests.helpers import load_spec

    out = exported(export_run, tmp_path / "failures", "--format", "imagefolder", "--unevaluable", "flag")
    replay = export_run / "replay.toml"
    replay.write_text(SPEC.replace('name = "export"', 'name = "replay"').replace(
        'type = "grid"', f'type = "table"\nfile = "{out / "design.csv"}"'))
    plan = plan_spec(load_spec(replay))
    jobs = sorted(plan.jobs + plan.out_of_frame, key=lambda job: job.index)
    exported_keys = [entry["image_key"] for entry in manifest(out)["items"]]
    assert [job.image_key for job in jobs] == exported_keys and len(exported_keys) >= 4


def test_the_same_export_twice_writes_the_same_files_and_appending_keeps_ids_unique(export_run: Path,
                                                                                    tmp_path: Path) -> None:
    for form in ("coco", "imagefolder", "parquet"):
        args = ("--format", form, "--where", "true")
        once = tree(exported(export_run, tmp_path / f"{form}-a", *args))
        assert once == tree(exported(export_run, tmp_path / f"{form}-b", *args))
        # half, then all appended: the same ids as one export of all, none repeated
        part = exported(export_run, tmp_path / f"{form}-c", *args[:2], "--where", "job < 5")
        exported(export_run, part, *args, "--append")
        ids = [e["id"] for e in manifest(part)["items"]]
        assert ids == list(range(1, len(ids) + 1)) and len(ids) == 6
        if form == "parquet":  # one file per export: the same rows
            both = pa.concat_tables(pq.read_table(p) for p in sorted((part / "data").glob("*.parquet")))
            assert both.equals(pq.read_table(tmp_path / f"{form}-a" / "data" / "train-00000.parquet"))
            assert tree(part)["design.csv"] == once["design.csv"]
        else:
            assert tree(part) == once
    before = tree(part)
    code, output = export(export_run, "-o", str(part), *args, "--append")  # all there already
    assert code == 0 and "6 already in the export" in output and tree(part) == before


# -- bad input: one line, exit 2, nothing written ------------------------------------------------
def one_line_error(folder: Path, *args: str) -> str:
    code, output = export(folder, *args)
    lines = [line for line in output.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error:"), output
    return lines[0]


@pytest.mark.parametrize("args, text", [
    (("--format", "yolo"), "--format 'yolo': unknown export format 'yolo'; valid: coco, imagefolder, parquet, or "),
    (("--format", "coc"), "(did you mean 'coco'?)"),
    (("--format", "coco", "--where", "NOT correct; DROP TABLE results"), "holds a ';'"),
    (("--format", "coco", "--where", "true) UNION ALL (SELECT * FROM results"), "is not only a condition"),
    (("--format", "coco", "--where", "true) ORDER BY (job"), "is not only a condition"),
    (("--format", "coco", "--where", "correct ="), "does not parse"),
    (("--format", "coco", "--unevaluable", "maybe"), "--unevaluable 'maybe': use skip or flag"),
    (("--format", "parquet", "--link"), "--link: a parquet export holds the images' bytes"),
])
def test_bad_options_are_one_line_and_write_nothing(tmp_path: Path, args: tuple[str, ...], text: str) -> None:
    write_spec(tmp_path, TINY_SPEC)
    assert text in one_line_error(tmp_path, *args, "-o", str(tmp_path / "out"))
    assert not (tmp_path / "out").exists() and not list(tmp_path.glob(".out*"))


def test_an_output_folder_with_other_files_is_refused(tmp_path: Path) -> None:
    write_spec(tmp_path, TINY_SPEC)
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert "already holds files" in one_line_error(tmp_path, "--format", "coco", "-o", str(out))
    assert "not a sweep3d export" in one_line_error(tmp_path, "--format", "coco", "-o", str(out), "--append")
    assert "inside the store" in one_line_error(tmp_path, "--format", "coco", "-o", str(tmp_path / "store" / "x"))
    assert [p.name for p in out.iterdir()] == ["notes.txt"] and not (tmp_path / "store").exists()


def classification_store(folder: Path) -> None:
    """TINY_SPEC in ``folder`` and a store of its three results made by hand (no render, no truth
    passes): jobs 0 and 2 failed, job 1 is right; job ``i``'s image is a (4 + i)×4 PNG."""
    from datetime import datetime

    from sweep3d.spec.columns import PARAMETERS_METADATA

    write_spec(folder, TINY_SPEC)
    store = Store(folder / "store")
    jobs = [{"experiment": "tiny", "job": i, "object": "box", "environment": "white", "orientation_yaw": 45.0 * i,
             "render_key": f"ab{i}", "image_key": f"ab{i}", "pred_key": f"p{i}", "in_frame": True, "model": "m"}
            for i in range(3)]
    table = pa.Table.from_pylist(jobs).replace_schema_metadata({PARAMETERS_METADATA: json.dumps(["orientation_yaw"])})
    store.write_table_file(store.jobs_path("tiny"), table)
    store.append("predictions", [{"pred_key": f"p{i}", "image_key": f"ab{i}", "valid": True, "correct": i == 1,
                                  "top1_label": "x", "loss": 1.0, "created_at": datetime(2024, 1, 1)} for i in range(3)])
    for i in range(3):
        store.blob_path(f"ab{i}").parent.mkdir(parents=True, exist_ok=True)
        store.blob_path(f"ab{i}").write_bytes(_png(4 + i, 4))


def test_a_run_without_the_mask_pass_exports_folders_but_not_coco(tmp_path: Path) -> None:
    """A classification store (made by hand: no truth passes) exports its failures as an ImageFolder;
    COCO, which needs the masks, is refused in one line before anything is written."""
    classification_store(tmp_path)
    assert "mask pass" in one_line_error(tmp_path, "--format", "coco", "-o", str(tmp_path / "coco"))
    assert not (tmp_path / "coco").exists() and not list(tmp_path.glob(".coco*"))
    out = exported(tmp_path, tmp_path / "folder", "--format", "imagefolder")
    assert sorted(p.name for p in (out / "carton").iterdir()) == ["000001.png", "000002.png"]  # jobs 0 and 2 failed
    assert (out / "carton" / "000002.png").read_bytes() == _png(6, 4)
    assert (out / "design.csv").read_text() == "object,environment,orientation_yaw\nbox,white,0.0\nbox,white,90.0\n"


def test_where_is_one_condition_as_duckdb_parses_it() -> None:
    for fine in ("NOT correct", "object = 'a;b' AND job > 1", "job IN (SELECT job FROM results WHERE correct)",
                 "correct -- a comment"):
        assert check_where(fine) == fine
    for bad in ("", "true) LIMIT (1", "1; SELECT 2", "DROP TABLE results"):
        with pytest.raises(UserError):
            check_where(bad)


def test_the_design_table_leaves_a_control_that_does_not_apply_empty() -> None:
    items = [{"design": {"object": "a", "environment": "w", "yaw": 45.0, "scale_factor": None}},
             {"design": {"object": "b", "environment": "w", "yaw": 0.0, "scale_factor": 0.5, "flag": True}}]
    assert design_table(items).decode().splitlines() == [
        "object,environment,yaw,scale_factor,flag", "a,w,45.0,,", "b,w,0.0,0.5,true"]
    assert class_folder("coffee mug") == "coffee mug" and "/" not in class_folder("a/b") != class_folder("a_b")


def test_bad_where_and_a_damaged_blob_on_a_real_run_write_nothing(export_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert "no_such_column" in one_line_error(export_run, "--format", "coco", "-o", str(out),
                                              "--where", "no_such_column > 1")
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(export_run, copy)
    key = results(copy)[0]["image_key"]
    Store(copy / "store").blob_path(key).write_bytes(b"not the image")
    code, output = export(copy, "--format", "coco", "-o", str(out), "--where", "true")
    lines = output.strip().splitlines()  # the progress bar's last line, then the error
    assert code == 2 and "no longer matches its recorded digest" in lines[-1] and "Traceback" not in output, output
    assert not out.exists() and not list(tmp_path.glob(".out*"))
    assert filecmp.cmp(copy / "spec.toml", export_run / "spec.toml")


# -- a user's own format: --format module:Name, a DatasetWriter beside the spec -----------------
#: A format of one JSON line per image and its PNG, read through the public plug-in API only.
JSONL_WRITER = '''
import json

from sweep3d.plugins import DatasetWriter


class Jsonl(DatasetWriter):
    def file_of(self, item):
        return f"png/{item.stem}"

    def write(self, batch, folder, staging, progress):
        lines = []
        for item in batch.items:
            staging.write(self.file_of(item), batch.store.blob_path(item.row["image_key"]).read_bytes())
            lines.append(json.dumps({"id": item.id, "label": item.label, "job": item.attributes["job"]}))
            progress.advance()
        old = (folder.root / "labels.jsonl").read_text() if not folder.fresh else ""
        staging.write("labels.jsonl", (old + "".join(line + "\\n" for line in lines)).encode())
'''


@pytest.fixture
def user_module(monkeypatch):
    """Write a plug-in module beside the spec in a folder; sys.path and the module forgotten afterwards."""
    import sys

    monkeypatch.setattr(sys, "path", [*sys.path])  # the export puts the spec's folder first on it
    written: list[str] = []

    def write(folder: Path, name: str, source: str) -> None:
        (folder / f"{name}.py").write_text(source)
        written.append(name)

    yield write
    for name in written:
        sys.modules.pop(name, None)


def test_a_user_s_writer_beside_the_spec_exports_and_appends_through_the_command_line(tmp_path: Path,
                                                                                      user_module) -> None:
    classification_store(tmp_path)
    user_module(tmp_path, "jsonl_format", JSONL_WRITER)
    out = exported(tmp_path, tmp_path / "out", "--format", "jsonl_format:Jsonl")
    lines = [json.loads(line) for line in (out / "labels.jsonl").read_text().splitlines()]
    assert lines == [{"id": 1, "label": "carton", "job": 0}, {"id": 2, "label": "carton", "job": 2}]  # the failures
    assert (out / "png" / "000002.png").read_bytes() == _png(6, 4)
    assert manifest(out)["format"] == "jsonl_format:Jsonl" and [e["file"] for e in manifest(out)["items"]] == [
        "png/000001.png", "png/000002.png"]
    assert (out / "design.csv").read_text().splitlines()[1:] == ["box,white,0.0", "box,white,90.0"]
    exported(tmp_path, out, "--format", "jsonl_format:Jsonl", "--where", "true", "--append")
    assert [json.loads(line)["job"] for line in (out / "labels.jsonl").read_text().splitlines()] == [0, 2, 1]
    other = one_line_error(tmp_path, "-o", str(out), "--format", "imagefolder", "--append")
    assert "it is a jsonl_format:Jsonl export, not imagefolder" in other


@pytest.mark.parametrize("source, text", [
    ("raise RuntimeError('no licence')\n", "--format 'broken_format:Bad': export format module 'broken_format' "
                                           "(broken_format.py:1) failed to import: RuntimeError: no licence"),
    ("class Bad:\n    pass\n", "--format 'broken_format:Bad': is class Bad, not a sweep3d DatasetWriter subclass"),
    ("def Bad():\n    pass\n", "--format 'broken_format:Bad': is a function, not a sweep3d DatasetWriter subclass"),
    ("Good = 1\n", "module 'broken_format' has no export format named 'Bad'"),
    ("from sweep3d.plugins import DatasetWriter\nclass Bad(DatasetWriter):\n    def __init__(self):\n"
     "        raise ValueError('needs a path')\n",
     "export format 'broken_format:Bad' (broken_format.py:4) failed to start: ValueError: needs a path"),
    ("from sweep3d.plugins import DatasetWriter\nclass Bad(DatasetWriter):\n    def write(self, batch, folder, "
     "staging, progress):\n        staging.write('half.txt', b'x')\n        raise KeyError('label')\n",
     "export format 'broken_format:Bad' (broken_format.py:5) failed in write(): KeyError: 'label'"),
    ("import sys\nfrom sweep3d.plugins import DatasetWriter\nclass Bad(DatasetWriter):\n    def write(self, *args):\n"
     "        sys.exit(0)\n", "export format 'broken_format:Bad' (broken_format.py:5) called sys.exit(0)"),
])
def test_a_broken_user_writer_is_one_line_naming_it_and_writes_nothing(tmp_path: Path, user_module, source: str,
                                                                       text: str) -> None:
    classification_store(tmp_path)
    user_module(tmp_path, "broken_format", source)
    code, output = export(tmp_path, "--format", "broken_format:Bad", "-o", str(tmp_path / "out"))
    lines = output.strip().splitlines()  # a failure inside write() follows the progress bar's last line
    errors = [line for line in lines if line.startswith("error:")]
    assert code == 2 and errors == lines[-1:] and len(lines) <= 2 and "Traceback" not in output, output
    assert text in errors[0]
    assert not (tmp_path / "out").exists() and not list(tmp_path.glob(".out*"))
