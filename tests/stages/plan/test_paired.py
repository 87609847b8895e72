"""Paired designs: ``[policy] paired`` shares draws across scenes, ``stratify`` balances lists, and the
paired views (McNemar on the same poses) count what a hand count does. Plans only, nothing rendered."""

from __future__ import annotations

import hashlib
import json
import math
import random
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.spec.framing import Framing
from sweep3d.spec.space import SpaceShape
from sweep3d.stages.plan import make_plan
from sweep3d.stages.plan.policies import RandomPolicy, balanced
from tests.helpers import (
    TINY_SPEC,
    every_job,
    examples,
    load_spec,
    make_store,
    paired_spec,
    rows_of,
    scene_values,
    write_spec,
)

FAST = settings(max_examples=examples(150), deadline=None)

RANDOM = 'type = "random"\nsamples = 7'
SOBOL = 'type = "sobol"\nsamples = 8'
GRID = 'type = "grid"\nsamples_per_dim = 3'
#: Digests of every job (scene, values, render and image keys; prediction keys are the infer
#: stage's) of paired_spec at seed 3, computed with the planner of commit 4c31124, before paired designs
#: existed: an unpaired plan must not move.
BEFORE = {RANDOM: (28, "40178db6e481b99e"), SOBOL: (32, "315cddc08e619c3e"), GRID: (216, "01f038408e976e36")}


def plan(folder: Path, policy: str, seed: int = 3):
    sub = folder / f"spec{len(list(folder.iterdir()))}"
    sub.mkdir()
    loaded = load_spec(write_spec(sub, paired_spec(seed=seed, policy=policy)))
    return make_plan(loaded, framing=Framing.full(32), model_digest="m", blender="4.5.0")




def fingerprint(p) -> tuple[int, str]:
    jobs = every_job(p)
    text = json.dumps([[j.object, j.environment, j.values, j.render_key, j.image_key] for j in jobs],
                      sort_keys=True, default=str)
    return len(jobs), hashlib.sha256(text.encode()).hexdigest()[:16]




# -- keys of unpaired plans do not move -------------------------------------------------------------


@pytest.mark.parametrize("policy", [RANDOM, SOBOL, GRID])
def test_unpaired_plans_are_those_made_before_paired_designs(tmp_path: Path, policy: str) -> None:
    assert fingerprint(plan(tmp_path, policy)) == BEFORE[policy]
    assert fingerprint(plan(tmp_path, policy + "\npaired = false")) == BEFORE[policy]
    if policy == RANDOM:
        assert fingerprint(plan(tmp_path, policy + "\nstratify = false")) == BEFORE[policy]


def test_a_paired_grid_is_the_grid(tmp_path: Path) -> None:
    """A grid draws nothing: its scenes already share their points."""
    assert fingerprint(plan(tmp_path, GRID + "\npaired = true")) == BEFORE[GRID]


# -- paired draws -------------------------------------------------------------------------------------


@pytest.mark.parametrize("policy", [RANDOM, RANDOM + "\nstratify = true"])
def test_paired_random_shares_each_control_across_environments(tmp_path: Path, policy: str) -> None:
    paired = plan(tmp_path, policy + "\npaired = true")
    for control in ("orientation", "blur"):
        values = scene_values(paired, control)
        # grey has an extra control (the camera): each control draws from a stream of its own, so these still pair
        assert values[("box", "white")] == values[("box", "grey")]
        assert values[("crate", "white")] == values[("crate", "grey")]
        if control == "orientation":
            assert values[("box", "white")] != values[("crate", "white")]
    unpaired = scene_values(plan(tmp_path, policy), "orientation")
    assert unpaired[("box", "white")] != unpaired[("box", "grey")]


def test_paired_all_shares_across_objects_and_follows_the_seed(tmp_path: Path) -> None:
    values = scene_values(plan(tmp_path, RANDOM + '\npaired = "all"'), "orientation")
    assert len({json.dumps(v) for v in values.values()}) == 1
    again = scene_values(plan(tmp_path, RANDOM + '\npaired = "all"'), "orientation")
    other = scene_values(plan(tmp_path, RANDOM + '\npaired = "all"', seed=4), "orientation")
    assert again == values and other != values


def test_paired_sobol_pairs_scenes_with_the_same_controls(tmp_path: Path) -> None:
    """Sobol points are joint over every dimension: scenes pair when their controls are the same."""
    body = paired_spec(seed=3, policy=SOBOL + "\npaired = true").replace('environments = ["grey"]', "")
    folder = tmp_path / "same"
    folder.mkdir()
    loaded = load_spec(write_spec(folder, body))
    same = scene_values(make_plan(loaded, framing=Framing.full(32), model_digest="m", blender="4.5.0"), "orientation")
    assert same[("box", "white")] == same[("box", "grey")] != same[("crate", "white")]
    extra = scene_values(plan(tmp_path, SOBOL + "\npaired = true"), "orientation")
    assert extra[("box", "white")] != extra[("box", "grey")]  # grey has the camera too: another sequence


# -- stratified lists ---------------------------------------------------------------------------------


@FAST
@given(st.integers(1, 500), st.integers(1, 12), st.integers(0, 2**32))
def test_stratified_lists_are_balanced(n: int, k: int, seed: int) -> None:
    counts = Counter(balanced(np.random.default_rng(seed), n, k).tolist())
    assert sum(counts.values()) == n and set(counts) <= set(range(k))
    assert all(counts[v] in (n // k, -(-n // k)) for v in range(k))


@FAST
@given(st.integers(1, 200), st.lists(st.integers(1, 6), min_size=1, max_size=3), st.integers(0, 2**32))
def test_stratified_random_policy_balances_every_list(n: int, sizes: list[int], seed: int) -> None:
    policy = RandomPolicy(RandomPolicy.Params(samples=n, stratify=True))
    shape = SpaceShape(1, tuple(sizes))
    unit, choice = policy.arrays(shape, seed, {})
    assert unit.shape == (n, 1) and choice.shape == (n, len(sizes))
    for d, k in enumerate(sizes):
        counts = Counter(choice[:, d].tolist())
        assert all(counts[v] in (n // k, -(-n // k)) for v in range(k))
    again = policy.arrays(shape, seed, {})
    assert np.array_equal(unit, again[0]) and np.array_equal(choice, again[1])


# -- bad input: one line, exit 2 ----------------------------------------------------------------------


# -- the paired views -----------------------------------------------------------------------------------


def synthetic(seed: int) -> list[dict[str, Any]]:
    """Two objects × three environments × four yaws × two skins; studio alone has an hdri rotation
    (a control of that environment only); some results invalid, some out of frame."""
    rng = random.Random(seed)
    rows = []
    for obj in ("mug", "ball"):
        for env in ("white", "studio", "forest"):
            for yaw in (0.5, 1.5, 2.5, 3.5):
                for skin in ("original", "zebra"):
                    row = {"object": obj, "environment": env, "orientation_yaw": yaw, "material_skin": skin,
                           "correct": rng.random() < 0.6, "valid": rng.random() > 0.1,
                           "in_frame": rng.random() > 0.1}
                    if env == "studio":
                        row["hdri_rotation"] = 10.0 * yaw
                    rows.append(row)
    return rows


def mcnemar(b: int, c: int) -> float:
    """The exact two-sided McNemar p-value by hand: twice the binomial tail at one half."""
    return 1.0 if b + c == 0 else min(1.0, 2 * sum(math.comb(b + c, k) for k in range(min(b, c) + 1)) / 2 ** (b + c))


def hand_count(rows: list[dict[str, Any]], parameter: str, a: str, b: str) -> dict[str, Any]:
    """Pairs by hand: same object and environment (or, for the environment, same object) and the same
    yaw and skin; rows that do not count (invalid, out of frame) leave their partner unpaired."""
    counted = [r for r in rows if r["valid"] and r["in_frame"]]
    shared = [k for k in ("object", "environment", "orientation_yaw", "material_skin") if k != parameter]
    side = {v: {tuple(r[k] for k in shared): r["correct"] for r in counted if r[parameter] == v} for v in (a, b)}
    both = side[a].keys() & side[b].keys()
    pairs = [(side[a][k], side[b][k]) for k in both]
    only_a, only_b = sum(x and not y for x, y in pairs), sum(y and not x for x, y in pairs)
    return {"n": len(pairs), "n_correct_a": sum(x for x, _ in pairs), "n_correct_b": sum(y for _, y in pairs),
            "a_right_b_wrong": only_a, "a_wrong_b_right": only_b, "p_value": pytest.approx(mcnemar(only_a, only_b))}


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_paired_views_equal_a_hand_count(tmp_path: Path, seed: int) -> None:
    rows = synthetic(seed)
    con = make_store(tmp_path, rows)
    fields = ["n", "n_correct_a", "n_correct_b", "a_right_b_wrong", "a_wrong_b_right", "p_value"]
    environments = rows_of(con, "SELECT * FROM paired_environments")
    assert [(r["environment_a"], r["environment_b"]) for r in environments] == [
        ("white", "studio"), ("white", "forest"), ("studio", "forest")]  # spec (job) order
    for r in environments:
        assert {f: r[f] for f in fields} == hand_count(rows, "environment", r["environment_a"], r["environment_b"])
        assert r["accuracy_a"] == pytest.approx(r["n_correct_a"] / r["n"])
    [skins] = rows_of(con, "SELECT * FROM paired_values WHERE parameter = 'material_skin'")
    assert (skins["value_a"], skins["value_b"]) == ("original", "zebra")
    assert {f: skins[f] for f in fields} == hand_count(rows, "material_skin", "original", "zebra")
    holm = sorted(r["p_value"] for r in environments)
    assert min(r["p_holm"] for r in environments) == pytest.approx(min(1.0, 3 * holm[0]))


def test_a_configuration_seen_twice_pairs_once(tmp_path: Path) -> None:
    """One to one: a pose that occurs twice on one side and once on the other makes one pair."""
    rows = [{"environment": "a", "c_x": 1, "correct": True}, {"environment": "a", "c_x": 1, "correct": True},
            {"environment": "b", "c_x": 1, "correct": False}, {"environment": "b", "c_x": 2, "correct": False}]
    con = make_store(tmp_path, rows)
    [pair] = rows_of(con, "SELECT * FROM paired_environments")
    assert (pair["n"], pair["a_right_b_wrong"], pair["a_wrong_b_right"]) == (1, 1, 0)
    assert [r["job_a"] for r in rows_of(con, "SELECT * FROM paired_jobs WHERE parameter = 'environment'")] == [0]


# -- the report panel -----------------------------------------------------------------------------------

PANEL_SPEC = TINY_SPEC.replace("yaw = [0, 45]", "yaw = { range = [0, 360] }").replace(
    '[[controls]]\ntype = "blur"\nsigma = [0.0, 1.5]', '[[controls]]\ntype = "material"\nskin = ["original", "zebra"]')


class Thumbs:
    """Stands in for the page's thumbnails: an index per image key asked for."""

    def __init__(self) -> None:
        self.keys: list[str] = []

    def want(self, key: str) -> int:
        self.keys.append(key)
        return len(self.keys) - 1


@pytest.mark.parametrize("paired", [True, False])
def test_the_panel_shows_paired_numbers_only_for_a_paired_spec(tmp_path: Path, paired: bool) -> None:
    from sweep3d.report.page import environment
    from sweep3d.report.panel import PanelInputs
    from sweep3d.report.panels import paired as panel

    policy = '[policy]\ntype = "random"\nsamples = 4' + ("\npaired = true" if paired else "")
    loaded = load_spec(write_spec(tmp_path, PANEL_SPEC.replace('[policy]\ntype = "grid"', policy)))
    rows = synthetic(1)
    con = make_store(tmp_path, rows)
    inputs = PanelInputs(loaded, con, None, None, Thumbs(), 2, None)  # type: ignore[arg-type]
    data = panel.build(inputs)
    if not paired:
        assert data is None
        return
    assert [(r["a"], r["b"]) for r in data["environments"]] == [("white", "studio"), ("white", "forest"),
                                                                ("studio", "forest")]
    assert [(r["parameter"], r["a"], r["b"]) for r in data["others"]] == [("material_skin", "original", "zebra")]
    expected = hand_count(rows, "material_skin", "original", "zebra")
    assert (data["others"][0]["n"], data["others"][0]["a_only"]) == (expected["n"], expected["a_right_b_wrong"])
    for left, right in data["examples"]["pairs"]:
        assert left["outcome"] != right["outcome"]
    html = environment().from_string('{% import "_macros.html.j2" as m with context %}'
                                     '{% include "panels/paired.html.j2" %}').render(data=data, spec_path="s.toml")
    assert "only A right" in html and "material_skin" in html and "paired_environments" in html


def test_a_post_control_added_to_a_paired_random_spec_renders_nothing_new(tmp_path: Path) -> None:
    """Each control draws from its own stream: the orientation's draws, and so every render, stay."""
    before = plan(tmp_path, RANDOM + "\npaired = true")
    body = paired_spec(seed=3, policy=RANDOM + "\npaired = true").replace(
        "[policy]", '[[controls]]\ntype = "noise"\nstd = { range = [0, 0.1] }\n\n[policy]')
    folder = tmp_path / "more"
    folder.mkdir()
    after = make_plan(load_spec(write_spec(folder, body)), framing=Framing.full(32), model_digest="m", blender="4.5.0")
    assert [j.render_key for j in every_job(after)] == [j.render_key for j in every_job(before)]
    assert {j.image_key for j in every_job(after)}.isdisjoint(j.image_key for j in every_job(before))


def test_query_reads_the_paired_views(tmp_path: Path) -> None:
    rows = synthetic(2)
    make_store(tmp_path, rows, experiment="tiny").close()
    spec = write_spec(tmp_path, TINY_SPEC)  # experiment "tiny", store "store": the one just written
    result = CliRunner().invoke(app, ["query", str(spec), "SELECT environment_a, environment_b, n, p_value FROM "
                                      "paired_environments", "--format", "json"])
    assert result.exit_code == 0, result.output
    found = {(r["environment_a"], r["environment_b"]): r for r in json.loads(result.output)}
    expected = hand_count(rows, "environment", "white", "forest")
    assert found[("white", "forest")]["n"] == expected["n"]
    assert found[("white", "forest")]["p_value"] == expected["p_value"]
