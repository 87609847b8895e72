"""Derived measures as axes: the classifier's margin (and the visible fraction, the IoU where the
results have them) are binned levels of ``control_accuracy`` and axes of the report's explorer, and
never failure modes, pairs, sensitivities or rules (they are outcomes, not causes). Synthetic store."""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pyarrow as pa

from sweep3d.cache.store import Store
from sweep3d.report.reading import Results, materialise_views
from sweep3d.results import connect
from sweep3d.results.measures import MEASURES
from sweep3d.results.rules import rules_of
from tests.helpers import rows_of

T0 = datetime(2026, 1, 1, tzinfo=timezone.utc)


def store_with_margins(folder: Path, n: int = 300):
    """Results whose margin (the true class "mug", first, less the best other) decides them: right
    above 0.3."""
    rng = np.random.default_rng(4)
    store = Store(folder / "store")
    jobs, predictions = [], []
    for i in range(n):
        first = float(rng.uniform(0.35, 1.0))
        second = float(rng.uniform(0.0, 1.0 - first)) if i % 7 else float("nan")  # some NaN: no margin
        key = f"k{i}"
        jobs.append({"experiment": "e", "job": i, "object": ("mug", "cup")[i % 2], "environment": "env",
                     "blur_sigma": (0.0, 1.5)[i % 3 == 0], "render_key": key, "image_key": key, "pred_key": key})
        right = bool(first - second > 0.3) if second == second else True
        predictions.append({"pred_key": key, "image_key": key, "created_at": T0, "valid": True, "correct": right,
                            "top1_label": "mug", "topk": [0, 1], "topk_labels": ["mug", "cup"],
                            "topk_probs": [first, second], "label_ids": [0] if i % 7 else [],
                            "label_prob": first if i % 7 else None, "loss": 1.0})  # no true class: no margin
    store.write_table_file(store.jobs_path("e"), pa.Table.from_pylist(jobs))
    store.append("predictions", predictions)
    return connect(store, "e")


def test_the_margin_is_a_binned_axis_of_control_accuracy_and_never_a_failure_mode(tmp_path: Path) -> None:
    con = store_with_margins(tmp_path)
    levels = rows_of(con, "SELECT label, value, absent, n, n_correct FROM control_accuracy WHERE parameter = 'margin' "
                          "ORDER BY level")
    present = [r for r in levels if not r["absent"]]
    assert len(present) == 10  # binned like any numeric parameter with many values
    assert [r for r in levels if r["absent"]][0]["n"] == len(range(0, 300, 7))  # NaN: no value, not averaged
    for r in present:  # the model is right exactly above 0.3: bins below all wrong, above all right
        if r["value"] + 0.06 < 0.3:
            assert r["n_correct"] == 0
        elif r["value"] - 0.06 > 0.3:
            assert r["n_correct"] == r["n"]
    assert rows_of(con, "SELECT numeric, binned FROM control_parameters WHERE parameter = 'margin'") == [
        {"numeric": True, "binned": True}]
    for sql in ("SELECT parameter_a AS p FROM failure_modes(min_count := 2)",
                "SELECT parameter_b AS p FROM failure_modes(min_count := 2) WHERE size = 2",
                "SELECT parameter_a AS p FROM pair_accuracy UNION ALL SELECT parameter_b FROM pair_accuracy",
                "SELECT parameter_a AS p FROM variance_explained", "SELECT parameter AS p FROM object_sensitivity"):
        assert not {r["p"] for r in rows_of(con, sql)} & set(MEASURES), sql
    assert rows_of(con, "SELECT count(*) AS n FROM failure_modes(min_count := 2)")[0]["n"] > 0  # blur, objects: tested
    assert all(c.column not in MEASURES for rule in rules_of(con) for c in rule.conditions)


def test_the_explorer_takes_the_margin_as_an_axis_after_the_parameters(tmp_path: Path) -> None:
    con = store_with_margins(tmp_path)
    materialise_views(con)
    results = Results(con, ["object", "environment", "blur_sigma"], MEASURES)
    assert [p.name for p in results.parameters] == ["object", "environment", "blur_sigma"]
    assert [p.name for p in results.measures] == ["margin"] and results.measures[0].binned
    margin = len(results.parameters)
    counts = results.counts([margin])
    expected = rows_of(con, "SELECT level, n FROM control_accuracy WHERE parameter = 'margin' ORDER BY level")
    assert dict(zip(counts["level"][0], counts["n"])) == {r["level"]: r["n"] for r in expected}
