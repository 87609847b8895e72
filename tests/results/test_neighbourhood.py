"""The views over the stability check's scene rows, on hand-made rows: a flip under a neighbour is
fragile as an image change's is, ``stability_images`` tells the two apart, and
``neighbourhood_accuracy`` counts a job correct only if it and every neighbour are."""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import pyarrow as pa
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sweep3d.cache.store import Store
from sweep3d.followups.stability.check import SCHEMA, stability_key
from sweep3d.followups.stability.scene import scene_key
from sweep3d.results import connect
from tests.helpers import examples

T0 = datetime(2024, 1, 1, tzinfo=timezone.utc)


def _prediction(key: str, correct: bool, margin: float) -> dict[str, Any]:
    """A two-class prediction whose true class is 0, ``margin`` from the other verdict."""
    p = (1 + abs(margin)) / 2
    order = [0, 1] if correct else [1, 0]
    return {"pred_key": key, "image_key": key, "created_at": T0, "valid": True, "correct": correct,
            "top1": order[0], "top1_label": f"c{order[0]}", "topk": order, "topk_labels": [f"c{i}" for i in order],
            "topk_probs": [p, 1 - p], "label_prob": p if correct else 1 - p, "loss": 1.0, "label_ids": [0]}


def _store(folder: Path, jobs: list[tuple[str, bool]]) -> Store:
    """One job per (object, correct), keys k0, k1, ..."""
    store = Store(folder / "store")
    rows = [{"experiment": "e", "job": i, "object": obj, "environment": "env", "c_a": 0, "render_key": f"k{i}",
             "image_key": f"k{i}", "pred_key": f"k{i}"} for i, (obj, _) in enumerate(jobs)]
    store.write_table_file(store.jobs_path("e"), pa.Table.from_pylist(rows))
    store.append("predictions", [_prediction(f"k{i}", ok, 0.6 if ok else -0.6) for i, (_, ok) in enumerate(jobs)])
    return store


def _row(key: str, change: str, base: bool, now: bool, neighbour: str | None) -> dict[str, Any]:
    margin = 0.6 if base else -0.6
    return {"stability_key": scene_key(key, change, neighbour) if neighbour else stability_key(key, change, 0),
            "pred_key": key, "image_key": key, "change": change, "seed": None if neighbour else 0,
            "base_correct": base, "base_margin": margin, "correct": now, "margin": margin if now == base else -margin,
            "flipped": base != now, "created_at": T0, "neighbour_key": neighbour}


def test_a_flip_under_a_neighbour_is_fragile_and_told_apart_from_an_image_change(tmp_path: Path) -> None:
    store = _store(tmp_path, [("a", True), ("a", False), ("b", True)])
    store.append("stability", [_row("k0", "noise", True, True, None), _row("k1", "noise", False, True, None),
                               _row("k2", "noise", True, True, None)], SCHEMA)
    con = connect(store, "e")
    assert con.execute("SELECT fragile FROM results WHERE pred_key = 'k0'").fetchone()[0] is False
    con.close()
    store.append("stability", [_row("k0", "yaw+1°", True, False, "n0"),  # k0 flips in the scene only
                               _row("k1", "yaw+1°", False, False, "n1")], SCHEMA)  # k1 in the image only
    con = connect(store, "e")
    images = {r[0]: r[1:] for r in con.execute(
        "SELECT pred_key, flipped, flipped_image, flipped_scene, neighbours FROM stability_images").fetchall()}
    assert images == {"k0": (True, False, True, 1), "k1": (True, True, False, 1), "k2": (False, False, None, 0)}
    assert con.execute("SELECT fragile FROM results WHERE pred_key = 'k0'").fetchone()[0] is True  # as an image flip


def test_old_rows_without_neighbour_key_read_as_image_changes(tmp_path: Path) -> None:
    store = _store(tmp_path, [("a", True)])
    old = [{k: v for k, v in _row("k0", "noise", True, False, None).items() if k != "neighbour_key"}]
    store.append("stability", old, pa.schema([f for f in SCHEMA if f.name != "neighbour_key"]))
    con = connect(store, "e")
    assert con.execute("SELECT flipped, flipped_image, flipped_scene FROM stability_images").fetchone() == \
        (True, True, None)
    assert con.execute("SELECT count(*) FROM neighbourhood_accuracy").fetchone()[0] == 0


jobs_strategy = st.lists(st.tuples(st.sampled_from(["a", "b", "c"]), st.booleans(),
                                   st.lists(st.booleans(), min_size=0, max_size=4)), min_size=1, max_size=12)


@settings(max_examples=examples(15), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(jobs_strategy)
def test_worst_of_neighbourhood_counts_a_job_only_if_it_and_every_neighbour_are_correct(tmp_path_factory,
                                                                                         jobs) -> None:
    folder = tmp_path_factory.mktemp("n")
    store = _store(folder, [(obj, ok) for obj, ok, _ in jobs])
    rows = [_row(f"k{i}", f"yaw{'+' if j % 2 else '-'}{j}°", ok, now, f"n{i}_{j}")
            for i, (_, ok, neighbours) in enumerate(jobs) for j, now in enumerate(neighbours)]
    rows += [_row(f"k{i}", "noise", ok, not ok, None) for i, (_, ok, _) in enumerate(jobs)]  # never counted here
    store.append("stability", rows, SCHEMA)
    con = connect(store, "e")
    got = {r[0]: r[1:] for r in con.execute(
        "SELECT object, images, neighbours, correct, worst_correct, accuracy, worst_accuracy, flipped "
        "FROM neighbourhood_accuracy").fetchall()}
    checked = [(obj, ok, n) for obj, ok, n in jobs if n]  # a job counts once a neighbour of it is compared
    for scope in [None, *sorted({obj for obj, _, _ in checked})] if checked else []:
        mine = [(ok, n) for obj, ok, n in checked if scope is None or obj == scope]
        correct = sum(ok for ok, _ in mine)
        worst = sum(ok and all(n) for ok, n in mine)
        flipped = sum(any(x != ok for x in n) for ok, n in mine)
        assert got[scope] == (len(mine), sum(len(n) for _, n in mine), correct, worst,
                              pytest.approx(correct / len(mine)), pytest.approx(worst / len(mine)), flipped)
        assert got[scope][3] <= got[scope][2]  # never above plain accuracy
    assert set(got) == ({None} | {obj for obj, _, _ in checked} if checked else set())
    con.close()
