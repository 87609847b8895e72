"""Alternatives without crossing: each base scene gets exactly one of several treatments (none, a
plate, a plant), as environments that share a background, each treatment's control limited to its
environment and the draws crossed with the environments. Planned only; results synthetic."""

from __future__ import annotations

from pathlib import Path

from sweep3d.results.rules import rules_of
from sweep3d.spec.framing import Framing
from sweep3d.stages.plan import make_plan
from tests.helpers import SPEC_ENVIRONMENTS, every_job, load_spec, make_store, rows_of, spec_toml, write_spec

TREATMENTS = ("none", "plate", "plant")
#: One environment per treatment, all on the same grey background.
SPEC = spec_toml("treatments", seed=2, render={"resolution": 32}, objects=("box", "crate"),
                 environments=[(t, SPEC_ENVIRONMENTS["grey"]) for t in TREATMENTS], body="""\
[[controls]]
type = "orientation"
yaw = { range = [-180, 180] }
pitch = { range = [-20, 20] }

[[controls]]
type = "occlusion"
id = "plate"
coverage = { range = [0.3, 0.7] }
environments = ["plate"]

[[controls]]
type = "occlusion"
id = "plant"
coverage = { range = [0.3, 0.7] }
grey = 0.2
direction = 90
environments = ["plant"]

[policy]
type = "random"
samples = 6
cross = ["environment"]
""")


def planned(folder: Path):
    loaded = load_spec(write_spec(folder, SPEC))
    return loaded, make_plan(loaded, framing=Framing.full(32), model_digest="m", blender="4.5.0")


def test_each_base_scene_gets_each_treatment_once_without_crossed_or_duplicate_jobs(tmp_path: Path) -> None:
    _, plan = planned(tmp_path)
    jobs = sorted(every_job(plan), key=lambda j: j.index)
    assert len(jobs) == 2 * 3 * 6  # objects × treatments × base draws: nothing crossed
    assert all(len({"plate", "plant"} & set(j.values)) <= 1 for j in jobs)  # never two occluders
    assert all(("plate" in j.values) == (j.environment == "plate") for j in jobs)
    assert len({j.render_key for j in jobs}) == len(jobs)  # no duplicate render
    for obj in ("box", "crate"):
        poses = {t: [j.values["orientation"] for j in jobs if j.scene == (obj, t)] for t in TREATMENTS}
        assert poses["none"] == poses["plate"] == poses["plant"]  # paired by base scene


def test_accuracy_per_treatment_is_paired_and_never_pools_a_controls_absent_jobs(tmp_path: Path) -> None:
    loaded, plan = planned(tmp_path)
    rows = []
    for job in plan.table().to_pylist():  # the jobs table a run writes: NULL where a control is absent
        row = {name: job[name] for name in ("object", "environment", *loaded.parameter_columns)}
        plate = row["plate_coverage"]
        row["correct"] = plate is None or plate < 0.5  # the plate hurts when it covers half; the plant never
        rows.append(row)
    con = make_store(tmp_path, rows)
    levels = rows_of(con, "SELECT label, absent, n FROM control_accuracy WHERE parameter = 'plate_coverage'")
    absent = [r for r in levels if r["absent"]]
    assert len(absent) == 1 and absent[0]["label"] == "(not applied)" and absent[0]["n"] == 2 * 2 * 6
    assert sum(r["n"] for r in levels if not r["absent"]) == 2 * 6  # only the plate's own jobs
    modes = rows_of(con, "SELECT label_a, label_b FROM failure_modes(min_count := 2)")
    assert all("(not applied)" not in (r["label_a"], r["label_b"]) for r in modes)
    assert any(r["label_a"] == "plate" and r["label_b"] is None for r in modes)  # the plate treatment is worse
    pairs = {(r["environment_a"], r["environment_b"]): r for r in rows_of(con, "FROM paired_environments")}
    assert set(pairs) == {("none", "plate"), ("none", "plant"), ("plate", "plant")}
    assert all(r["n"] == 2 * 6 for r in pairs.values())  # every base scene paired across treatments
    assert rules_of(con)[0].key() == "environment = plate"  # rules read a control's absent jobs as no value
    truth = sum(r["correct"] for r in rows if r["environment"] == "plate") / 12
    assert pairs[("none", "plate")]["accuracy_b"] == truth and pairs[("none", "plate")]["accuracy_a"] == 1.0
