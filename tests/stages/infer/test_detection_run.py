"""Detection end to end with real renders: an oracle detector built from the mask pass scores 100 %
and AP 1.0, the same oracle shifted by 60 % of the box's width scores 0 %, and a broken detector
or a label it lacks stops the run in one line, before anything is rendered.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from sweep3d.cache.blobs import load_image, load_pass
from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.core.truth import box
from tests.helpers import load_spec, plan_for, spec_toml, write_spec

pytestmark = [pytest.mark.slow, pytest.mark.blender, pytest.mark.torch]

#: The test's detector: it knows each stored image's true box (read from the mask pass by the
#: test) and answers with it, or with it shifted; the other factories break the rules.
ORACLE = '''
import hashlib, json, os
import numpy as np
import torch
from sweep3d.stages.infer import Detector, Segmenter

CLASSES = ["background", "carton", "crate"]
TABLE = json.loads(open(os.environ["ORACLE_BOXES"]).read())
BOXES, MASKS = TABLE.get("boxes", {}), TABLE.get("masks", {})


def digest(image):
    return hashlib.sha256(np.ascontiguousarray(image.permute(1, 2, 0).numpy()).tobytes()).hexdigest()


class Oracle(torch.nn.Module):
    def __init__(self, shift=0.0, bad=None):
        super().__init__()
        self.shift, self.bad = shift, bad

    def forward(self, images):
        out = []
        for image in images:
            found = BOXES.get(digest(image))
            boxes = torch.tensor([found], dtype=torch.float32) if found else torch.zeros((1, 4))
            boxes[:, [0, 2]] += self.shift * (boxes[:, 2] - boxes[:, 0])[:, None]
            if self.bad == "nan":
                boxes[0, 0] = float("nan")
            if self.bad == "shape":
                boxes = boxes[:, :3]
            out.append({"boxes": boxes, "labels": torch.tensor([1]), "scores": torch.tensor([0.9])})
        return out


def oracle():
    return Detector(Oracle(), labels=CLASSES)


class MaskOracle(torch.nn.Module):
    def forward(self, images):
        scores = torch.zeros((len(images), len(CLASSES), *images.shape[-2:]))
        for i, image in enumerate(images):
            pixels = MASKS.get(digest(image * 0.5 + 0.5), [])  # undo the default normalisation
            scores[i, 0] = 1.0
            scores[i, 1].view(-1)[pixels] = 2.0
        return {"out": scores}


def segmenter():
    from sweep3d.stages.infer.models import Normalize
    return Segmenter(MaskOracle(), Normalize(mean=(0.5,) * 3, std=(0.5,) * 3), labels=CLASSES)


def shifted():
    return Detector(Oracle(shift=0.6), labels=CLASSES)


def nan_boxes():
    return Detector(Oracle(bad="nan"), labels=CLASSES)


def three_columns():
    return Detector(Oracle(bad="shape"), labels=CLASSES)
'''


def spec_text(factory: str = "oracle", kind: str = "detection", label: str = "carton", extra: str = "") -> str:
    return spec_toml("detect", seed=1, render={"resolution": 48, "samples": 1, "denoise": False},
                     model={"name": f"oracle_detector:{factory}"}, objects=(("box", "cube.obj", [label]),), body=f"""\
[evaluator]
kind = "{kind}"
{extra}

[[controls]]
type = "orientation"
yaw = [0, 45]

[[controls]]
type = "position"
x = [-0.3, 0.3]

[policy]
type = "grid"
""")


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    """A store with the renders and their mask pass, and the oracle's table of true boxes."""
    folder = tmp_path_factory.mktemp("detect")
    (folder / "oracle_detector.py").write_text(ORACLE)
    (folder / "boxes.json").write_text("{}")
    # renders and masks first (the classifier's run: render keys do not depend on the model)
    spec = write_spec(folder, spec_text(kind="classification", extra='passes = ["mask"]').replace(
        "oracle_detector:oracle", "efficientnet-lite0"))
    with pytest.MonkeyPatch.context() as patch:
        patch.syspath_prepend(str(folder))
        patch.setenv("ORACLE_BOXES", str(folder / "boxes.json"))
        result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
        assert result.exit_code == 0, result.output
    store = Store(folder / "store")
    boxes, masks = {}, {}
    for job in plan_for(load_spec(spec)).jobs:
        import hashlib

        image = load_image(store, job.render_key, None)
        mask = load_pass(store, job.truth_key, "mask")
        digest = hashlib.sha256(np.ascontiguousarray(image).tobytes()).hexdigest()
        boxes[digest] = list(box(mask)) if mask.any() else None
        masks[digest] = np.flatnonzero(mask).tolist()
    (folder / "boxes.json").write_text(json.dumps({"boxes": boxes, "masks": masks}))
    return folder


def run(folder: Path, monkeypatch, name: str, **spec) -> tuple[int, str, Path]:
    sub = folder / name
    sub.mkdir()
    for item in ("cube.obj",):
        (sub / item).write_bytes((folder / item).read_bytes())
    path = write_spec(sub, spec_text(**spec).replace('store = "store"', f'store = "{folder / "store"}"'))
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.setenv("ORACLE_BOXES", str(folder / "boxes.json"))
    import sys

    sys.modules.pop("oracle_detector", None)  # the box table changed: load it again
    result = CliRunner().invoke(app, ["run", str(path), "--no-report"])
    return result.exit_code, result.output, path


def query(folder: Path, sql: str):
    from sweep3d.results import connect

    return connect(Store(folder / "store"), "detect").execute(sql).fetchall()


def test_the_oracle_scores_everything_and_ap_one(rendered: Path, monkeypatch) -> None:
    code, output, path = run(rendered, monkeypatch, "oracle", factory="oracle")
    assert code == 0, output
    rows = query(rendered, "SELECT correct, outcome, iou, score, false_positives FROM results WHERE evaluable")
    assert len(rows) == 4 and all(r[:3] == (True, "correct", 1.0) and r[4] == 0 for r in rows)
    assert query(rendered, "SELECT ap50, ap75, ap FROM average_precision WHERE object IS NULL") == [(1.0, 1.0, 1.0)]
    # the report shows the same numbers, from the same view
    from sweep3d.report import write_report

    page = write_report(load_spec(path)).read_text()
    table = page[page.index("<h3>Average precision</h3>"):]
    table = table[:table.index("</table>")]
    assert "mean over objects" in table and table.count("<td>100.0</td>") == 6  # mean and box: AP50, AP75, AP


def test_the_shifted_oracle_scores_nothing(rendered: Path, monkeypatch) -> None:
    code, output, _ = run(rendered, monkeypatch, "shifted", factory="shifted")
    assert code == 0, output
    rows = query(rendered, "SELECT correct, outcome, iou FROM results WHERE evaluable")
    assert len(rows) == 4 and all(not r[0] and r[1] == "wrong_box" and r[2] < 0.5 for r in rows)
    assert query(rendered, "SELECT ap50 FROM average_precision WHERE object IS NULL") == [(0.0,)]


def test_the_mask_oracle_segments_every_object(rendered: Path, monkeypatch) -> None:
    code, output, _ = run(rendered, monkeypatch, "segment", factory="segmenter", kind="segmentation")
    assert code == 0, output
    rows = query(rendered, "SELECT correct, outcome, iou, pred_pixels = true_pixels FROM results WHERE evaluable")
    assert len(rows) == 4 and all(r == (True, "correct", 1.0, True) for r in rows)


@pytest.mark.parametrize(("spec", "words"), [
    ({"factory": "nan_boxes"}, ("oracle_detector:nan_boxes", "NaN")),
    ({"factory": "three_columns"}, ("oracle_detector:three_columns", "(K, 4)")),
    ({"factory": "oracle", "label": "cartoon"}, ("objects[0].labels[0]", "carton")),
    ({"factory": "oracle", "kind": "classification"}, ("Detector", "detection")),
    ({"factory": "oracle", "kind": "segmentaton"}, ("evaluator", "segmentation")),
])
def test_bad_detectors_and_labels_stop_the_run_in_one_line(rendered: Path, monkeypatch, spec, words) -> None:
    before = {p.name: p.stat().st_size for p in (rendered / "store").rglob("*.parquet")}
    code, output, path = run(rendered, monkeypatch, "bad" + str(abs(hash(str(spec)))), **spec)
    message = output.strip()
    assert code == 2 and "\n" not in message and "Traceback" not in message, output
    assert all(w in message for w in words), message
    assert {p.name: p.stat().st_size for p in (rendered / "store").rglob("*.parquet")} == before
