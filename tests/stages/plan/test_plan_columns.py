"""The planner's columns against the per-job recipe they replace.

``make_plan`` builds values, keys and the in-frame test over arrays; :func:`reference_jobs` is
the per-job loop it replaced (one ``SearchSpace.values``, ``Params`` model, key recipe and
``SceneState`` per job). Over random specs — built-in controls, users' controls that take the
slow paths, every policy — both must give the same jobs, bit for bit.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sweep3d.assets.sources import blender_version
from sweep3d.cache.hashing import Hole, Template, canonical, float_texts
from sweep3d.core.control import wrap_periodic, wrap_periodic_many
from sweep3d.spec.framing import Framing
from sweep3d.spec.params import Range
from sweep3d.stages.plan import make_plan
from sweep3d.stages.render.state import SceneState, in_frame, in_frame_many
from tests.helpers import examples, finite, load_spec, reference_jobs, spec_toml, values, write_spec
from tests.helpers.plan_specs import specs


@settings(max_examples=examples(60), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(body=specs())
def test_the_columnar_plan_is_the_per_job_plan(tmp_path_factory, body: str) -> None:
    folder = tmp_path_factory.mktemp("spec")
    spec = load_spec(write_spec(folder, body))
    framing, blender = Framing.full(32), blender_version()
    plan = make_plan(spec, framing=framing, model_digest="model-x", blender=blender)
    jobs = sorted(list(plan.jobs) + list(plan.out_of_frame), key=lambda j: j.index)
    flagged = {j.index for j in plan.out_of_frame}
    got = [(j.index, j.object, j.environment, j.values, j.render_key, j.image_key, j.pred_key, j.point, j.parts_key,
            j.index not in flagged) for j in jobs]
    expected = reference_jobs(spec, framing=framing, model_digest="model-x", blender=blender)
    assert [repr(g) for g in got] == [repr(e) for e in expected]  # repr: -0.0 and 0.0 differ
    assert plan.table().equals(pa.Table.from_pylist(plan.rows()).replace_schema_metadata(plan.table().schema.metadata))
    _check_distinct_keys_from_columns(plan)


def _check_distinct_keys_from_columns(plan) -> None:
    """Each stage's distinct keys read from the columns are those its ``key`` gives job by job,
    in the same order, each with its first job."""
    from sweep3d.driver.jobs import JobList
    from sweep3d.stages.infer.infer_stage import InferStage
    from sweep3d.stages.postprocess.post_stage import PostprocessStage
    from sweep3d.stages.render.render_stage import RenderStage

    for jobs in (plan.jobs, plan.out_of_frame):
        if not isinstance(jobs, JobList):
            continue
        for stage in (RenderStage, PostprocessStage, InferStage):
            expected: dict[str, Any] = {}
            for job in jobs:
                key = stage.key(None, job)
                if key is not None:
                    expected.setdefault(key, job)
            fresh = JobList(jobs.columns, jobs.indices)  # nothing remembered, no job made
            got = fresh.unique_by(lambda j, s=stage: s.key(None, j), lambda js, s=stage: s.keys_of(None, js))
            assert fresh._jobs is None and list(got.keys()) == list(expected) and len(got) == len(expected)
            assert [got[key] for key in got] == list(expected.values())


# -- the vectorised pieces against their scalar forms ------------------------------------------



@settings(max_examples=examples(200), deadline=None)
@given(values=st.lists(finite, max_size=20))
def test_float_texts_are_what_canonical_writes(values: list[float]) -> None:
    texts = float_texts(np.array(values, dtype=np.float64)).tolist()
    assert texts == [canonical(v) for v in values]


@settings(max_examples=examples(200), deadline=None)
@given(values=st.lists(st.floats(-1e12, 1e12, allow_nan=False), max_size=20), period=st.sampled_from([8.0, 360.0, 2 * math.pi]))
def test_wrapping_many_angles_is_wrapping_each(values: list[float], period: float) -> None:
    wrapped = wrap_periodic_many(np.array(values, dtype=np.float64), period).tolist()
    assert [repr(w) for w in wrapped] == [repr(wrap_periodic(v, period)) for v in values]


@settings(max_examples=examples(200), deadline=None)
@given(bounds=st.lists(st.floats(-1e300, 1e300, allow_nan=False), min_size=2, max_size=2, unique=True),
       log=st.booleans(), integer=st.booleans(),
       units=st.lists(st.one_of(st.floats(-0.5, 1.5, allow_nan=False), st.sampled_from([0.0, -0.0, 1.0])), max_size=12))
def test_a_range_maps_many_points_as_it_maps_each(bounds, log, integer, units) -> None:
    low, high = sorted(bounds)
    log = log and low > 0
    integer = integer and max(abs(low), abs(high)) < 1e15
    space = Range(low, high, log=log, integer=integer)
    many = space.at_many(np.array(units, dtype=np.float64)).tolist()
    assert [repr(v) for v in many] == [repr(space.at(u)) for u in units]




@settings(max_examples=examples(200), deadline=None)
@given(value=st.dictionaries(st.text(max_size=4), values, max_size=4), filling=st.lists(values, min_size=2, max_size=2))
def test_a_template_filled_with_canonical_texts_is_the_canonical_text(value: dict, filling: list) -> None:
    template = Template({**value, "$a": Hole("a"), "z": [Hole("b")]})
    texts = {"a": [canonical(filling[0])], "b": [canonical(filling[1])]}
    assert template.fill(**texts) == [canonical({**value, "$a": filling[0], "z": [filling[1]]})]


def test_a_template_fills_keys_as_json_strings() -> None:
    template = Template({"render": Hole("render"), "stage": "x"})
    assert template.fill(["render"], render=["ab12"]) == [canonical({"render": "ab12", "stage": "x"})]


edge = st.floats(-3, 3, allow_nan=False)


@settings(max_examples=examples(300), deadline=None)
@given(scale=st.floats(0.05, 5), azimuth=st.floats(-360, 360), elevation=st.floats(-90, 90), zoom=st.floats(0.05, 20),
       focal=st.floats(1, 500), x=edge, y=edge)
def test_the_in_frame_test_over_arrays_is_the_scalar_one_where_it_is_sure(scale, azimuth, elevation, zoom, focal,
                                                                          x, y) -> None:
    state = SceneState(scale=scale, azimuth=azimuth, elevation=elevation, zoom=zoom, focal_length=focal,
                       frame_x=x, frame_y=y)
    fields = {"scale": scale, "azimuth": azimuth, "elevation": elevation, "zoom": zoom, "focal_length": focal,
              "frame_x": np.array([x]), "frame_y": y}
    inside, unsure = in_frame_many(fields, 1)
    assert unsure[0] or bool(inside[0]) == in_frame(state)


def test_states_on_the_frame_edge_are_left_to_the_scalar_test() -> None:
    """An object exactly touching a side plane: the array test may round either way, so it says so."""
    half = SceneState().half_fov()
    reach = SceneState().camera_distance() * math.tan(half)
    edge_x = (1.0 / math.cos(half)) / reach + 1.0  # centre one radius (along the plane's normal) beyond the side
    xs = np.array([edge_x, 0.0, 5.0])
    inside, unsure = in_frame_many({"frame_x": xs}, 3)
    assert unsure[0] and not unsure[1:].any()
    assert inside.tolist() == [False, True, False]


@pytest.mark.parametrize("policy", ['type = "grid"\nsamples_per_dim = 3', 'type = "random"\nsamples = 9'])
def test_planned_jobs_read_their_values_from_columns_and_compare_as_jobs(tmp_path: Path, policy: str) -> None:
    body = specs_example(policy)
    spec = load_spec(write_spec(tmp_path, body))
    plan = make_plan(spec, framing=Framing.full(32), model_digest="m", blender="4.5")
    job = plan.jobs[1]
    assert job.values["orientation"]["yaw"] == job.values["orientation"]["yaw"]
    assert set(job.values) == {"orientation"} and isinstance(job.values["orientation"]["yaw"], float)
    assert job == plan.jobs[1] and job != plan.jobs[0]
    assert plan.jobs == list(plan.jobs) and len(plan.jobs + plan.out_of_frame) == len(plan.jobs) + len(plan.out_of_frame)
    with pytest.raises(TypeError):
        hash(job)


def specs_example(policy: str) -> str:
    return spec_toml("columns", store=None, render={"resolution": 32}, body=f"""\
[[controls]]
type = "orientation"
yaw = {{ range = [-180, 180] }}

[policy]
{policy}
""")


def test_an_unchanged_plan_is_not_written_again_and_a_changed_one_is(tmp_path: Path, monkeypatch) -> None:
    from sweep3d.cache.store import Store
    from sweep3d.driver.jobs import Plan
    from sweep3d.runner.pipeline import write_jobs

    spec = load_spec(write_spec(tmp_path, specs_example('type = "random"\nsamples = 9')))
    store = Store(tmp_path / "store")
    plan = make_plan(spec, framing=Framing.full(32), model_digest="m", blender="4.5")
    write_jobs(plan, store)
    path = store.jobs_path(spec.name)
    written, original = path.stat(), path.read_bytes()
    again = make_plan(spec, framing=Framing.full(32), model_digest="m", blender="4.5")
    assert again.fingerprint() == plan.fingerprint()
    with monkeypatch.context() as patched:
        patched.setattr(Plan, "table", lambda self: pytest.fail("an unchanged plan's table is built again"))
        write_jobs(again, store)
    assert (path.stat().st_ino, path.stat().st_mtime_ns) == (written.st_ino, written.st_mtime_ns)
    data = bytearray(path.read_bytes())
    data[len(data) // 3] ^= 0xFF
    with open(path, "r+b") as fh:  # damaged in place, its size and mtime put back
        fh.write(data)
    os.utime(path, ns=(written.st_atime_ns, written.st_mtime_ns))
    write_jobs(again, store)
    assert path.read_bytes() == original, "a changed jobs file is written again"
    other = make_plan(spec, framing=Framing.full(32), model_digest="n", blender="4.5")  # other prediction keys
    assert other.fingerprint() != plan.fingerprint()
    write_jobs(other, store)
    assert pq.read_table(path).column("pred_key").to_pylist() == [j.pred_key for j in other.jobs]


@settings(max_examples=examples(200), deadline=None)
@given(st.lists(st.none() | st.text(alphabet="a\n", max_size=3), max_size=4),
       st.lists(st.none() | st.text(alphabet="a\n", max_size=3), max_size=4))
def test_columns_written_for_the_fingerprint_tell_different_values_apart(a: list, b: list) -> None:
    from sweep3d.driver.jobs import _list_bytes

    assert (_list_bytes(a) == _list_bytes(b)) == (a == b)


def test_a_stage_that_changes_its_key_alone_gets_its_own_keys_not_its_parents(tmp_path: Path) -> None:
    from sweep3d.driver.jobs import JobList
    from sweep3d.driver.loop import unique_jobs
    from sweep3d.stages.render import LOCAL
    from sweep3d.stages.render.render_stage import RenderStage

    class Prefixed(RenderStage):
        def key(self, job):
            return "x" + job.render_key

    spec = load_spec(write_spec(tmp_path, specs_example('type = "random"\nsamples = 9')))
    plan = make_plan(spec, framing=Framing.full(32), model_digest="m", blender="4.5")
    jobs = JobList(plan.jobs.columns, plan.jobs.indices)
    assert list(unique_jobs(Prefixed(LOCAL), jobs)) == ["x" + k for k in dict.fromkeys(j.render_key for j in jobs)]
    assert list(unique_jobs(RenderStage(LOCAL), jobs)) == list(dict.fromkeys(j.render_key for j in jobs))
