"""Rules over several parameters: subgroup discovery finds a planted box, names nothing where
nothing matters, and a rule's box is confirmed on fresh twins by an oracle that fails there."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sweep3d.followups.confirm.claims import rule_claim
from sweep3d.followups.confirm.draw import Parameter, Space, draw_pairs
from sweep3d.results.confirmation import CONFIRMED, judge, tally
from sweep3d.results.rules import find_rules, rule_dict, rules_of
from sweep3d.results.summary import named_rules, summarise
from sweep3d.spec.params import Choice, Range
from tests.helpers import make_store


def planted(seed: int, n: int = 600, effect: bool = True) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    columns = {"orientation_yaw": rng.uniform(-180, 180, n), "camera_elevation": rng.uniform(0, 80, n),
               "blur_sigma": rng.choice([0.0, 1.5, 3.0], n), "object": rng.choice(["mug", "toaster"], n).astype(object)}
    box = (columns["orientation_yaw"] > 80) & (columns["orientation_yaw"] <= 110) & (columns["camera_elevation"] > 40)
    wrong = rng.random(n) < (np.where(box, 0.8, 0.15) if effect else 0.25)
    return columns, ~wrong, box


def test_the_best_rule_is_the_planted_box_over_two_parameters() -> None:
    for seed in range(5):
        columns, correct, box = planted(seed)
        best = find_rules(columns, correct)[0]
        assert {c.column for c in best.conditions} == {"orientation_yaw", "camera_elevation"}
        inside = np.ones(len(correct), bool)
        for c in best.conditions:
            x = columns[c.column]
            inside &= (x > (c.low if c.low is not None else -np.inf)) & (x <= (c.high if c.high is not None else np.inf))
        # the box found holds most of the true one and is at most three times its size (the cuts are
        # quantiles, 30° of yaw apart: they cannot hit 80 and 110 exactly)
        assert (inside & box).sum() >= 0.7 * box.sum() and inside.sum() <= 3 * box.sum()
        assert best.accuracy < 0.6 and best.accuracy_rest > 0.75 and best.p_adjusted < 0.05
        assert best.difference_low <= best.difference <= best.difference_high < 0
        assert best.n == int(inside.sum()) and best.support == best.n / len(correct)


def test_where_nothing_matters_no_rule_is_named() -> None:
    named = 0
    for seed in range(40):
        columns, correct, _ = planted(seed, effect=False)
        named += any(r.p_adjusted < 0.05 and len(r.conditions) >= 2 for r in find_rules(columns, correct))
    assert named <= 2  # at most 5 % (Bonferroni over every box the search could form: conservative)


def test_a_rule_is_confirmed_on_fresh_twins_inside_its_box_and_elsewhere() -> None:
    columns, correct, _ = planted(1)
    best = find_rules(columns, correct)[0]
    space = Space(("mug", "toaster"), ("white",), (
        Parameter("orientation_yaw", "orientation", "yaw", Range(-180.0, 180.0),
                  frozenset({("mug", "white"), ("toaster", "white")})),
        Parameter("camera_elevation", "camera", "elevation", Range(0.0, 80.0),
                  frozenset({("mug", "white"), ("toaster", "white")})),
        Parameter("blur_sigma", "blur", "sigma", Choice((0.0, 1.5, 3.0)),
                  frozenset({("mug", "white"), ("toaster", "white")}))))
    claim = rule_claim(rule_dict(best), {p.column: p.space for p in space.parameters})
    assert claim.key == f"rule {best.key()}"

    def within(row) -> bool:
        return all(side.intervals[0][0] < row[column] <= side.intervals[0][1] or
                   (side.intervals[0][0] == row[column]) for column, side in claim.box)
    drawn = draw_pairs(space, claim, 32, seed=2)
    for inside, outside in drawn:
        assert within(inside) and not within(outside)
        assert inside["blur_sigma"] == outside["blur_sigma"] and inside["object"] == outside["object"]

    def truth(row) -> bool:
        return not (80 < row["orientation_yaw"] <= 110 and row["camera_elevation"] > 40)
    (verdict,) = judge([tally((truth(a), truth(b)) for a, b in drawn)])
    assert verdict.status == CONFIRMED


def test_the_summary_names_the_box_and_the_rules_view_lists_it(tmp_path: Path) -> None:
    columns, correct, _ = planted(3)
    rows = [{"orientation_yaw": float(columns["orientation_yaw"][i]), "camera_elevation":
             float(columns["camera_elevation"][i]), "blur_sigma": float(columns["blur_sigma"][i]),
             "correct": bool(correct[i])} for i in range(len(correct))]
    con = make_store(tmp_path, rows)
    summary = summarise(con, ["orientation_yaw", "camera_elevation", "blur_sigma"])
    (first, *_) = named_rules(summary)
    assert {c["column"] for c in first["conditions"]} == {"orientation_yaw", "camera_elevation"}
    assert first["text"].startswith(first["key"] + ": ") and "elsewhere" in first["text"]
    assert rules_of(con)[0].key() == first["key"]


def test_the_boxes_run_leaves_unnamed_are_counted() -> None:
    from sweep3d.results.summary import RULE_LIMIT, Summary, rules_left_out

    def box(p: float, conditions: int = 2) -> dict:
        return {"conditions": [{"column": f"c{i}"} for i in range(conditions)], "p_adjusted": p}

    named = [box(0.001), box(0.01), box(0.02)]  # three that qualify; one of a single condition, one not significant
    summary = Summary(jobs=0, evaluated=0, invalid=0, correct=0, accuracy=None, objects=[], environments=[],
                      scene_accuracy=[], scene_count=[], rules=[*named, box(0.001, conditions=1), box(0.2)])
    assert len(named_rules(summary)) == RULE_LIMIT == 2
    assert rules_left_out(summary) == 1
    assert rules_left_out(summary, limit=3) == 0
