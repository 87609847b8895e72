"""Class names that round-trip: ``results`` names a class as the spec did (``running shoe``, not
the model's ``sneaker``), the model's name beside it, so a label written in the spec selects its
rows. Stores here are planned from a real spec and their prediction rows made by the real
classification evaluator from synthetic logits: no Blender, no model."""

from __future__ import annotations

from pathlib import Path

import duckdb
import numpy as np
import pyarrow as pa
import pytest
from typer.testing import CliRunner

from sweep3d.assets.sources import blender_version
from sweep3d.cache.store import Store, segment_name, utc_now
from sweep3d.cli import app
from sweep3d.core.errors import SpecError
from sweep3d.report import write_report
from sweep3d.results import connect
from sweep3d.results.class_name_views import named_columns
from sweep3d.runner.pipeline import write_jobs
from sweep3d.spec.framing import Framing
from sweep3d.stages.infer.evaluators import ClassificationEvaluator
from sweep3d.stages.infer.evaluators.classification import ranked_rows
from sweep3d.stages.infer.evaluators.evaluator import Truth
from sweep3d.stages.infer.infer_stage import predictions_schema
from sweep3d.stages.infer.labels import IMAGENET, LabelMap
from sweep3d.stages.plan import make_plan
from tests.helpers import load_spec, spec_toml, write_spec

SNEAKER, CURTAIN, TEA_CUP = 770, 854, 968  # ImageNet's sneaker / running shoe, front / theater curtain, tea cup / cup

def names_spec(models: str = "") -> str:
    """Three objects on white, labelled by name (the cup by an ImageNet id, which names nothing:
    the model's name stands), and the ``models`` tables given."""
    return spec_toml("names", render={"resolution": 32}, objects=(
        ("shoe", "cube.obj", ["running shoe"]), ("curtain", "cube.obj", ["theater curtain"]), ("cup", "cube.obj", [968])),
        body=models + """
[[controls]]
type = "orientation"
yaw = [0, 90, 180, 270]

[policy]
type = "grid"
""")


#: What the model answers for each object, yaw by yaw: right, or another object's class.
ANSWERS = {"shoe": [SNEAKER, CURTAIN, SNEAKER, SNEAKER], "curtain": [CURTAIN, SNEAKER, SNEAKER, CURTAIN],
           "cup": [TEA_CUP, SNEAKER, TEA_CUP, CURTAIN]}


def _store(folder: Path, models: str = "", flip: bool = False) -> tuple[Path, duckdb.DuckDBPyConnection]:
    """Plan the spec (each model with a stand-in digest), write its jobs as a run does, and a
    prediction row per job from logits whose top class is :data:`ANSWERS`' (the next one with
    ``flip`` for every model after the first)."""
    spec = write_spec(folder, names_spec(models=models))
    loaded = load_spec(spec)
    plans = [make_plan(loaded, framing=Framing.full(32), model_digest=f"stand-in-{i}", blender=blender_version(),
                       model=settings, view=(256, 224)) for i, settings in enumerate(loaded.models)]
    store = Store(loaded.store)
    write_jobs(plans, store)
    evaluator = ClassificationEvaluator(ClassificationEvaluator.Params())
    rows = []
    for i, plan in enumerate(plans):
        for job in plan.jobs:
            answers = ANSWERS[job.object]
            step = int(job.values["orientation"]["yaw"]) // 90
            logits = np.zeros((1, len(IMAGENET)))
            logits[0, answers[(step + (1 if flip and i else 0)) % 4]] = 9.0
            logits[0, [SNEAKER, CURTAIN, TEA_CUP]] += [3.0, 2.0, 1.0]  # the rest of the top 5 names them too
            truth = Truth(loaded.labels[job.object])
            row = ranked_rows(logits, [truth], IMAGENET, evaluator.params.top_k)[0]
            rows.append({"pred_key": job.pred_key, "image_key": job.image_key, "model": plan.model,
                         "model_digest": plan.model_digest, "seconds": 0.0, "created_at": utc_now(), **row})
    table = pa.Table.from_pylist(rows, schema=predictions_schema(evaluator))
    store.write_table_file(store.table_dir("predictions") / segment_name(), table)
    return spec, connect(store, loaded.name)


def _jobs(con: duckdb.DuckDBPyConnection, where: str) -> set[int]:
    return {r[0] for r in con.execute(f"SELECT job FROM results WHERE {where}").fetchall()}


def test_a_class_name_from_the_spec_selects_exactly_the_rows_the_model_got_right(tmp_path: Path) -> None:
    spec, con = _store(tmp_path)
    for obj, name in (("shoe", "running shoe"), ("curtain", "theater curtain")):
        right = _jobs(con, f"object = '{obj}' AND correct")
        assert right and _jobs(con, f"object = '{obj}' AND top1_label = '{name}'") == right
    # Any object's image taken for a spec's class prints the spec's name, the model's beside it.
    assert con.execute("SELECT DISTINCT top1_model_label FROM results WHERE top1_label = 'running shoe'"
                       ).fetchall() == [("sneaker",)]
    assert _jobs(con, "top1_label = 'running shoe'") == _jobs(con, f"top1 = {SNEAKER}")
    assert not _jobs(con, "top1_label = 'sneaker'")
    # A label given as an id names nothing: the cup's class keeps the model's name.
    assert _jobs(con, "top1_label = 'tea cup'") == _jobs(con, "object = 'cup' AND correct") != set()
    topk, model_topk = con.execute("SELECT topk_labels, topk_model_labels FROM results LIMIT 1").fetchone()
    assert sorted(topk[:3]) == ["running shoe", "tea cup", "theater curtain"]
    assert sorted(model_topk[:3]) == ["front curtain", "sneaker", "tea cup"]
    assert ("shoe", "theater curtain") in con.execute("SELECT object, prediction FROM object_confusions").fetchall()

    printed = CliRunner().invoke(app, ["query", str(spec), "SELECT DISTINCT top1_label, top1_model_label FROM results "
                                       "ORDER BY 1", "--format", "csv"])
    assert printed.exit_code == 0, printed.output
    assert printed.output.splitlines() == ["top1_label,top1_model_label", "running shoe,sneaker", "tea cup,tea cup",
                                           "theater curtain,front curtain"]


def test_the_report_names_classes_as_the_spec_does_and_says_what_the_model_saw(tmp_path: Path) -> None:
    spec, con = _store(tmp_path)
    con.close()
    html = write_report(load_spec(spec)).read_text()
    assert "running shoe" in html and "theater curtain" in html
    assert "sneaker" not in html and "front curtain" not in html
    assert ('<p class="meta" id="protocol">resolution = 32: 32² renders, which the model resizes to 256² '
            "(upsampled 8×) and centre-crops to 224²</p>") in html


def test_compare_names_both_models_answers_as_the_spec_does(tmp_path: Path) -> None:
    models = '\n[[models]]\nname = "efficientnet-lite0"\n\n[[models]]\nname = "efficientnet-lite1"\n'
    _, con = _store(tmp_path, models, flip=True)
    pairs = con.execute("SELECT DISTINCT top1_a, top1_b FROM model_pairs WHERE object = 'shoe'").fetchall()
    assert {a for a, _ in pairs} | {b for _, b in pairs} == {"running shoe", "theater curtain"}


@pytest.mark.parametrize("labels, key", [
    ('["running shoe"]\n', None),  # the second object's label, below
    ('["running shoe", "sneaker"]\n', "objects[0].labels[1]"),
])
def test_two_labels_naming_one_class_differently_are_refused(tmp_path: Path, labels: str, key: str | None) -> None:
    text = names_spec(models="").replace('["running shoe"]\n', labels)
    if key is None:
        text = text.replace('["theater curtain"]', '["sneaker"]')
    spec = write_spec(tmp_path, text)
    with pytest.raises(SpecError) as caught:
        load_spec(spec)
    assert f"{key or 'objects[1].labels[0]'}: 'sneaker' is class 770, which objects[0].labels[0] calls " \
           "'running shoe'" in str(caught.value)
    result = CliRunner().invoke(app, ["plan", str(spec)])
    assert result.exit_code == 2 and "Traceback" not in result.output


def test_a_users_model_whose_classes_clash_is_refused_when_planned(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, names_spec(models='\n[model]\nname = "mymodels:shoes"\n')
                      .replace("[968]", '["sneaker"]'))
    loaded = load_spec(spec)  # a user's classes are unknown until its factory runs
    classes = LabelMap([["sneaker", "running shoe"], ["theater curtain"], ["cup"]])
    with pytest.raises(SpecError, match=r"objects\[2\]\.labels\[0\]: 'sneaker' is class 0"):
        make_plan(loaded, framing=Framing.full(32), model_digest="m", blender="4", classes=classes)


def test_without_ids_a_name_the_model_gives_two_classes_keeps_the_models_name() -> None:
    con = duckdb.connect()
    con.execute("CREATE TABLE p AS SELECT * FROM (VALUES ('sneaker'), ('missile'), ('dog')) t(top1_label)")
    names = {"m": [(1, "sneaker", "running shoe", False), (2, "missile", "projectile", True)]}
    named = named_columns({"top1_label": "VARCHAR"}, ["top1_label"], "top1_label", names, own_model=False)
    got = con.execute(f"SELECT {named['top1_label']}, {named['top1_model_label']} FROM p").fetchall()
    assert got == [("running shoe", "sneaker"), ("missile", "missile"), ("dog", "dog")]
    assert LabelMap([["missile"], ["missile", "projectile"]]).renamed({1: "projectile"}) == \
        [(1, "missile", "projectile", True)]


def test_spellings_of_one_name_are_one_name_printed_as_first_written(tmp_path: Path) -> None:
    text = names_spec(models="").replace('["theater curtain"]', '["Running-Shoe", "running shoe", "Theatre_Curtain"]')
    loaded = load_spec(write_spec(tmp_path, text))
    plan = make_plan(loaded, framing=Framing.full(32), model_digest="m", blender="4")
    assert list(plan.class_names) == [(SNEAKER, "sneaker", "running shoe", False),
                                      (CURTAIN, "front curtain", "Theatre_Curtain", False)]
