"""Evaluators as plug-ins: their own settings, their column roles, and the views that follow them.

No Blender and no model: specs are only loaded, stores are written row by row (as in
``test_tasks_report``), and evaluators are run on hand-made outputs.
"""

from __future__ import annotations

import itertools
import json
import re
from pathlib import Path
from typing import Any

import pyarrow as pa
import pytest

from sweep3d.cache.store import Store
from sweep3d.core.errors import PluginError, SpecError, UserError
from sweep3d.core.evaluation import EVALUATOR_METADATA, Roles, declaration_problem
from sweep3d.report import build_context, render_html
from sweep3d.report.panels import CORE_PANELS, PANELS
from sweep3d.results import connect, summarise
from sweep3d.spec.columns import MIN_VISIBLE_METADATA, PARAMETERS_METADATA
from sweep3d.stages.infer.evaluate import evaluate_checked
from sweep3d.stages.infer.evaluators import EVALUATORS, Evaluator, Truth
from sweep3d.stages.infer.labels import LabelMap
from sweep3d.stages.infer.prediction_keys import evaluator_key
from tests.helpers import (
    MIN_VISIBLE,
    PARAMETERS,
    T0,
    TINY_SPEC,
    TRUE_BOX,
    load_spec,
    prediction,
    synthetic_jobs,
    write_spec,
)
from tests.helpers import TASKS_SPEC as SPEC

pytestmark = pytest.mark.fast

USER_MODULE = '''
import pyarrow as pa
from pydantic import Field

from sweep3d.stages.infer import Evaluator, EvaluatorParams, Roles


class Depth(Evaluator):
    class Params(EvaluatorParams):
        tolerance: float = Field(0.1, gt=0)
        metric: str = "abs_rel"

    task = "raw"
    schema = pa.schema([("valid", pa.bool_()), ("ok", pa.bool_()), ("abs_rel", pa.float64())])
    roles = Roles(correct="ok", loss="abs_rel")

    def evaluate(self, outputs, truths, labels):
        return [{"valid": True, "ok": bool(o < self.params.tolerance), "abs_rel": float(o)}
                for o, _ in zip(outputs, truths)]
'''

_names = itertools.count()


def user_module(tmp_path: Path, monkeypatch, source: str = USER_MODULE) -> str:
    """A user's evaluator module on the import path, under a name of its own; returns the name."""
    name = f"user_evaluators_{next(_names)}"
    (tmp_path / f"{name}.py").write_text(source)
    monkeypatch.syspath_prepend(str(tmp_path))
    return name


def spec_with(tmp_path: Path, evaluator: str) -> Path:
    tmp_path.mkdir(parents=True, exist_ok=True)
    return write_spec(tmp_path, TINY_SPEC.replace("[policy]", f"[evaluator]\n{evaluator}\n\n[policy]"))


# -- settings -----------------------------------------------------------------------------------


def test_the_built_in_evaluators_key_on_their_own_settings_as_before() -> None:
    """The prediction keys' evaluator part is what it was when one constructor held every setting."""
    assert {kind: EVALUATORS.get(kind)().key_part() for kind in EVALUATORS.names()} == {
        "classification": {"top_k": 5}, "localization": {"top_k": 5, "iou": 0.5},
        "detection": {"iou": 0.5, "score": 0.5}, "segmentation": {"iou": 0.5}}
    assert EVALUATORS.get("detection")(iou=0.7, score=0.3).key_part() == {"iou": 0.7, "score": 0.3}


@pytest.mark.parametrize("evaluator, key, message", [
    ('kind = "classification"\ntop_kk = 3', "evaluator.top_kk",
     "unknown setting for evaluator 'classification' (did you mean 'top_k'?); valid: kind, passes, min_visible, top_k"),
    ('kind = "detection"\ntop_k = 3', "evaluator.top_k",
     "unknown setting for evaluator 'detection'; valid: kind, passes, min_visible, iou, score"),
    ('kind = "detection"\niou = 1.5', "evaluator.iou", "less than or equal to 1"),
    ('kind = "segmentation"\niou = "half"', "evaluator.iou", "valid number"),
])
def test_a_setting_the_evaluator_does_not_have_or_a_bad_value_is_one_line(tmp_path: Path, evaluator: str, key: str,
                                                                        message: str) -> None:
    with pytest.raises(SpecError) as caught:
        load_spec(spec_with(tmp_path, evaluator))
    assert caught.value.key == key and message in caught.value.problem
    assert "\n" not in str(caught.value)


def test_a_user_evaluator_gets_its_own_settings_in_its_instance_and_its_key(tmp_path: Path, monkeypatch) -> None:
    module = user_module(tmp_path, monkeypatch)
    loaded = load_spec(spec_with(tmp_path, f'kind = "{module}:Depth"\ntolerance = 0.25'))
    evaluator = EVALUATORS.get(loaded.evaluator.kind).from_settings(loaded.evaluator)
    assert evaluator.params.tolerance == 0.25 and evaluator.params.metric == "abs_rel"
    key = evaluator_key(loaded.evaluator)
    assert key.pop("code").startswith("source:")  # its code's identity (registry.code_identity)
    assert key == {"kind": f"{module}:Depth", "tolerance": 0.25, "metric": "abs_rel"}
    other = load_spec(spec_with(tmp_path / "b", f'kind = "{module}:Depth"\ntolerance = 0.5'))
    assert evaluator_key(other.evaluator) != evaluator_key(loaded.evaluator)  # another setting, other keys
    with pytest.raises(SpecError, match=r"evaluator\.top_k: unknown setting for evaluator .*valid: kind, passes, "
                                        r"min_visible, tolerance, metric"):
        load_spec(spec_with(tmp_path / "c", f'kind = "{module}:Depth"\ntop_k = 3'))


# -- roles --------------------------------------------------------------------------------------


def test_every_built_in_evaluator_declares_roles_that_fit_its_schema() -> None:
    for kind in EVALUATORS.names():
        assert declaration_problem(EVALUATORS.get(kind)) is None, kind
    assert EVALUATORS.get("detection").roles.has("detection_scores")
    assert not EVALUATORS.get("classification").roles.has("outcome")


@pytest.mark.parametrize("change, problem", [
    ('roles = Roles(correct="ok", loss="abs_rel")', None),
    ('roles = Roles(loss="abs_rel")', "its correct column 'correct' is not in its schema"),
    ('roles = Roles(correct="abs_rel")', "its correct column 'abs_rel' is double, not bool"),
    ('roles = Roles(correct="ok", outcome="abs_rel")', "its outcome column 'abs_rel' is double, not a string"),
    ('roles = {"correct": "ok"}', "its roles is not a Roles"),
    ('schema = None', "declares no pyarrow schema"),
    ('Params = dict', "its Params is not an EvaluatorParams model"),
])
def test_roles_are_checked_against_the_schema_when_the_spec_loads(tmp_path: Path, monkeypatch, change: str,
                                                                  problem: str | None) -> None:
    source = USER_MODULE.replace('    roles = Roles(correct="ok", loss="abs_rel")', f"    {change}")
    module = user_module(tmp_path, monkeypatch, source)
    spec = spec_with(tmp_path, f'kind = "{module}:Depth"')
    if problem is None:
        assert load_spec(spec).evaluator.kind == f"{module}:Depth"
        return
    with pytest.raises(SpecError) as caught:
        load_spec(spec)
    assert caught.value.key == "evaluator.kind" and problem in caught.value.problem


def test_a_role_s_usual_name_taken_by_another_column_is_refused() -> None:
    schema = pa.schema([("valid", pa.bool_()), ("hit", pa.bool_()), ("correct", pa.bool_())])
    assert "its column 'correct' would be hidden by its correct column 'hit'" in Roles(correct="hit").problem(schema)


# -- a store shared by a classification and a detection experiment ------------------------------


def shared_store(folder: Path) -> tuple[Path, Path]:
    """One store, two experiments on the same jobs: ``cls`` (classification) and ``det`` (detection,
    with its detections for AP); returns their specs."""
    jobs = [j for j in synthetic_jobs() if j.evaluable is not False]  # every job evaluable: no such panel
    store = Store(folder / "store")
    specs = []
    for name, kind in (("cls", "classification"), ("det", "detection")):
        text = SPEC.replace('name = "tasks"', f'name = "{name}"').replace('passes = ["mask"]',
                                                                       f'kind = "{kind}"\npasses = ["mask"]')
        specs.append(write_spec(folder, text, name=f"{name}.toml"))
        rows, predictions = [], []
        for job in jobs:
            key = f"{name}{job.job}"
            rows.append({"experiment": name, "job": job.job, "object": job.object, "environment": "white",
                         "orientation_yaw": job.yaw, "blur_sigma": job.sigma, "render_key": f"r{job.job}",
                         "image_key": f"r{job.job}", "pred_key": key, "truth_key": f"t{job.job}", "in_frame": True})
            row = prediction(key, f"r{job.job}", job, kind, "m")
            if kind == "detection":
                row.update(det_scores=[0.9] if job.iou is not None else [], det_ious=[job.iou] if job.iou else [])
            predictions.append(row)
        metadata = {PARAMETERS_METADATA: json.dumps(PARAMETERS).encode(), MIN_VISIBLE_METADATA: str(MIN_VISIBLE).encode(),
                    EVALUATOR_METADATA: EVALUATORS.get(kind).record(kind).to_json()}
        store.write_table_file(store.jobs_path(name), pa.Table.from_pylist(rows).replace_schema_metadata(metadata))
        store.append("predictions", predictions)
    store.append("truths", [{"truth_key": f"t{j.job}", "render_key": f"r{j.job}", "passes": ["mask"],
                             **dict(zip(("gt_x0", "gt_y0", "gt_x1", "gt_y1"), TRUE_BOX)),
                             "visible_pixels": j.visible, "silhouette_pixels": 750, "visible_fraction": j.fraction,
                             "created_at": T0} for j in jobs if j.truth])
    return specs[0], specs[1]


def views(con) -> set[str]:
    return {r[0] for r in con.execute("SELECT view_name FROM duckdb_views() WHERE NOT internal").fetchall()}


def test_each_experiment_of_a_shared_store_shows_only_its_own_task(tmp_path: Path) -> None:
    cls_spec, det_spec = shared_store(tmp_path)
    task_views = {"average_precision", "average_precision_by_value", "outcomes_by_value", "iou_by_object"}
    pages = {}
    for spec, kind in ((cls_spec, "classification"), (det_spec, "detection")):
        loaded = load_spec(spec)
        store = Store(loaded.store)
        con = connect(store, loaded.name)
        assert con.execute("SELECT DISTINCT kind FROM evaluator").fetchall() == [(kind,)]
        columns = {r[0] for r in con.execute("DESCRIBE results").fetchall()}
        evaluator = EVALUATORS.get(kind)
        others = {c for k in EVALUATORS.names() for c in EVALUATORS.get(k).schema.names} - set(evaluator.schema.names)
        assert not columns & others, f"{kind}'s results carry another evaluator's columns"
        pages[kind] = (views(con), build_context(loaded, con, store))
        summary = summarise(connect(store, loaded.name), PARAMETERS)
        own = con.execute("SELECT count(*) FROM predictions WHERE starts_with(pred_key, ?)",
                          [loaded.name]).fetchone()[0]
        assert summary.evaluated == own  # its own predictions, none of the other experiment's

    cls_views, cls_page = pages["classification"]
    assert not cls_views & task_views
    # its numeric lists add the failure boundaries panel, and no task's panel is added
    assert [p.id for p in cls_page["panels"]] == [p.id for p in PANELS if p in CORE_PANELS or p.id == "boundaries"]
    html = render_html(cls_page)
    assert "Average precision" not in html and not re.search(r"<code>(average_precision|outcomes_by_value)", html)

    det_views, det_page = pages["detection"]
    assert task_views <= det_views
    outcomes = next(p for p in det_page["panels"] if p.id == "outcomes").data
    assert outcomes["precision"] and outcomes["outcomes"] and outcomes["iou"] is not None
    assert cls_page["summary"].counted == det_page["summary"].counted  # the same jobs, each counted once


def test_a_plan_without_a_recorded_evaluator_still_reads_by_its_columns(tmp_path: Path) -> None:
    """A jobs file from before plans recorded their evaluator: the roles its columns suggest."""
    cls_spec, _ = shared_store(tmp_path)
    store = Store(load_spec(cls_spec).store)
    jobs = store.jobs_path("cls")
    table = pa.parquet.read_table(jobs)
    metadata = {k: v for k, v in (table.schema.metadata or {}).items() if k != EVALUATOR_METADATA}
    store.write_table_file(jobs, table.replace_schema_metadata(metadata))
    con = connect(store, "cls")
    assert con.execute("SELECT DISTINCT kind FROM evaluator").fetchone()[0] == "(not recorded)"
    assert con.execute("SELECT count(*) FROM results WHERE counted").fetchone()[0] > 0


# -- what an evaluator returns ------------------------------------------------------------------


class Returns(Evaluator):
    """An evaluator that returns whatever it is told to."""

    schema = pa.schema([("valid", pa.bool_()), ("correct", pa.bool_()), ("score", pa.float64())])
    rows: Any = None

    def evaluate(self, outputs, truths, labels):
        if isinstance(self.rows, Exception):
            raise self.rows
        return self.rows


LABELS = LabelMap(["a", "b"])
TRUTHS = [Truth((0,))] * 5


@pytest.mark.parametrize("rows, message", [
    (ValueError("the depth map is empty\nsecond line"), "failed: ValueError: the depth map is empty"),
    ([{"valid": "yes"}] * 5, "returned valid = 'yes', which is not bool as its schema says"),
    ([{"valid": True, "correct": True}] * 4, "returned 4 rows for 5 images; return one row per image"),
    ([{"valid": True, "score": 0.5}] * 5, "returned no 'correct' in valid row 0 (its correctness column)"),
    ([{"valid": True, "correct": True, "extra": 1}] * 5, "returned column 'extra' (row 0), which is not in its schema"),
    ({"valid": True}, "returned dict, not a list of one dict per image"),
])
def test_an_evaluator_that_breaks_its_contract_stops_in_one_line_naming_it(rows: Any, message: str) -> None:
    evaluator = Returns()
    evaluator.rows = rows
    with pytest.raises(PluginError) as caught:
        evaluate_checked(evaluator, "mymod:Returns", None, TRUTHS, LABELS)
    text = str(caught.value)
    assert re.match(r"evaluator mymod:Returns \(test_evaluator_plugins\.py:\d+\) ", text), text
    assert message in text and "\n" not in text
    assert isinstance(caught.value, UserError) and caught.value.exit_code == 2


def test_rows_that_keep_the_contract_pass_unchanged() -> None:
    evaluator = Returns()
    evaluator.rows = [{"valid": True, "correct": i % 2 == 0, "score": 0.1 * i} for i in range(4)] + [{"valid": False}]
    assert evaluate_checked(evaluator, "mymod:Returns", None, TRUTHS, LABELS) == evaluator.rows


def test_the_docs_evaluator_loads_and_its_rows_pass_the_checks(tmp_path: Path, monkeypatch) -> None:
    """The depth evaluator of the docs (how-to/own-evaluator.md), without a render: its settings, roles and rows, and the
    line its failure message names."""
    import numpy as np

    from tests.helpers.doc_blocks import block, page_text

    (tmp_path / "mydepth.py").write_text(block("how-to/own-evaluator.md", "# Your own evaluator"))
    monkeypatch.syspath_prepend(str(tmp_path))
    loaded = load_spec(spec_with(tmp_path, 'kind = "mydepth:DepthError"\ntolerance = 0.05'))
    evaluator = EVALUATORS.get("mydepth:DepthError").from_settings(loaded.evaluator)
    assert evaluator.params.tolerance == 0.05 and evaluator.roles.loss == "abs_rel"
    mask = np.zeros((4, 4), bool)
    mask[1:3, 1:3] = True
    depth = np.full((4, 4), 2.0, np.float32)
    truths = [Truth((0,), mask=mask, depth=depth), Truth((0,), mask=np.zeros((4, 4), bool), depth=depth)]
    rows = evaluate_checked(evaluator, "mydepth:DepthError", np.full((2, 1, 4, 4), 2.05), truths, LABELS)
    assert rows[0] == {"valid": True, "correct": True, "abs_rel": pytest.approx(0.025)}
    assert rows[1]["valid"] is False
    assert f"(mydepth.py:{type(evaluator).where().split(':')[1]}) failed" in page_text("how-to/own-evaluator.md")
