"""The plan's keys read back from the store's memo are the keys planning writes and hashes.

A memo read under the wrong fingerprint would hand a plan another plan's keys: every cached
result would then be a wrong one. So each test plans with the memo and without it and compares
the jobs bit for bit, over random specs and over pairs of them that share the memo's file.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sweep3d.assets.sources import blender_version
from sweep3d.cache import Store
from sweep3d.spec.framing import Framing
from sweep3d.stages.plan import keys_memo, make_plan, planner
from tests.helpers import examples, load_spec, write_spec
from tests.helpers.plan_specs import specs

pytestmark = pytest.mark.fast

FRAMING = Framing.full(32)


def _plan(spec, store: Store | None = None, model: str = "model-x"):
    return make_plan(spec, framing=FRAMING, model_digest=model, blender=blender_version(), remember=store)


def _keys(plan) -> list[tuple]:
    jobs = sorted(list(plan.jobs) + list(plan.out_of_frame), key=lambda j: j.index)
    return [(j.index, j.render_key, j.image_key, j.pred_key, j.parts_key, j.truth_key) for j in jobs]


def _same(a, b) -> None:
    assert _keys(a) == _keys(b)
    assert a.table().equals(b.table())
    assert a.fingerprint() == b.fingerprint()


@pytest.fixture
def every_plan(monkeypatch):
    monkeypatch.setattr(keys_memo, "MIN_JOBS", 0)


class Counted:
    """Counts the scenes whose keys are written and hashed (not read back)."""

    def __init__(self, monkeypatch) -> None:
        self.calls = 0
        real = planner._scene_keys

        def counted(*args, **kwargs):
            self.calls += 1
            return real(*args, **kwargs)

        monkeypatch.setattr(planner, "_scene_keys", counted)


@settings(max_examples=examples(30), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(body=specs())
def test_keys_read_back_are_the_keys_planned(tmp_path_factory, monkeypatch, every_plan, body: str) -> None:
    folder = tmp_path_factory.mktemp("spec")
    spec = load_spec(write_spec(folder, body))
    store = Store(folder / "store")
    fresh = _plan(spec)
    written = _plan(spec, store)
    counted = Counted(monkeypatch)
    read = _plan(spec, store)
    _same(fresh, written)
    _same(fresh, read)
    assert counted.calls == 0 or not len(fresh.jobs) + len(fresh.out_of_frame)  # read back, not hashed


@settings(max_examples=examples(40), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(first=specs(), second=specs(), model=st.sampled_from(["model-x", "model-y"]))
def test_another_plan_in_the_same_file_plans_its_own_keys(tmp_path_factory, every_plan, first: str, second: str,
                                                          model: str) -> None:
    """Two specs of one experiment (one memo file): the second is never given the first's keys."""
    folder = tmp_path_factory.mktemp("spec")
    store = Store(folder / "store")
    a = load_spec(write_spec(folder, first, name="a.toml"))
    b = load_spec(write_spec(folder, second, name="b.toml"))
    _plan(a, store)
    _same(_plan(b, store, model), _plan(b, model=model))
    _same(_plan(a, store), _plan(a))


def test_a_changed_value_plans_again(tmp_path, monkeypatch, every_plan) -> None:
    """One bound of one range moved: the memo is not used, and the new keys replace it."""
    body = _body("yaw = { range = [-180, 180] }")
    store = Store(tmp_path / "store")
    _plan(load_spec(write_spec(tmp_path, body)), store)
    moved = load_spec(write_spec(tmp_path, _body("yaw = { range = [-180, 179.5] }")))
    counted = Counted(monkeypatch)
    _same(_plan(moved, store), _plan(moved))
    assert counted.calls > 0
    calls = counted.calls
    _plan(moved, store)
    assert counted.calls == calls  # remembered in place of the old


def test_other_code_plans_again(tmp_path, monkeypatch, every_plan) -> None:
    spec = load_spec(write_spec(tmp_path, _body("yaw = { range = [-180, 180] }")))
    store = Store(tmp_path / "store")
    _plan(spec, store)
    monkeypatch.setattr(keys_memo, "_code_digest", lambda: "another sweep3d")
    counted = Counted(monkeypatch)
    _plan(spec, store)
    assert counted.calls > 0


@pytest.mark.parametrize("damage", ["truncated", "flipped", "folder"])
def test_a_damaged_memo_is_a_miss(tmp_path, monkeypatch, every_plan, damage: str) -> None:
    spec = load_spec(write_spec(tmp_path, _body("yaw = { range = [-180, 180] }")))
    store = Store(tmp_path / "store")
    fresh = _plan(spec, store)
    (path,) = (tmp_path / "store" / "cache" / "plan-keys").iterdir()
    data = path.read_bytes()
    if damage == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif damage == "flipped":
        middle = len(data) // 3
        path.write_bytes(data[:middle] + bytes([data[middle] ^ 0xFF]) + data[middle + 1:])
    else:
        path.unlink()
        path.mkdir()
    counted = Counted(monkeypatch)
    _same(_plan(spec, store), fresh)
    assert counted.calls > 0


def test_small_plans_and_adaptive_rounds_are_not_remembered(tmp_path) -> None:
    spec = load_spec(write_spec(tmp_path, _body("yaw = { range = [-180, 180] }")))
    _plan(spec, Store(tmp_path / "store"))
    assert not (tmp_path / "store" / "cache" / "plan-keys").exists()  # 40 jobs < MIN_JOBS


def _body(yaw: str) -> str:
    from tests.helpers import spec_toml

    return spec_toml("memo", seed=3, store="store", render={"resolution": 32, "samples": 1}, body=f"""\
[[controls]]
type = "orientation"
{yaw}
pitch = {{ range = [-90, 90] }}

[[controls]]
type = "blur"
sigma = {{ range = [0, 2] }}

[policy]
type = "random"
samples = 40
""")
