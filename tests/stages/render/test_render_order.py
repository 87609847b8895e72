"""How render work is ordered and shared, and what a worker keeps loaded: no Blender needed.

A worker keeps every object and world it has loaded, but Cycles rebuilds a world's importance
map whenever the scene's world changes; so jobs go world by world, each worker renders a
contiguous share of that order, and what a worker keeps is bounded (least recently used out).
"""

from __future__ import annotations

from pathlib import Path

from sweep3d.cache.store import Store
from sweep3d.stages.render.kept import Kept
from sweep3d.stages.render.pool import Shares
from sweep3d.stages.render.render_stage import _groups
from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderJob
from tests.helpers import TINY_SPEC, load_spec, plan_for, write_cube, write_spec

TWO_OBJECTS = TINY_SPEC.replace("[[environments]]", """[[objects]]
name = "crate"
mesh = "crate.obj"
labels = ["crate"]

[[environments]]""", 1)


def test_groups_go_world_by_world_then_object_by_object(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, TWO_OBJECTS)
    write_cube(tmp_path, "crate.obj")
    plan = plan_for(load_spec(spec), "model-x")
    groups = _groups(plan, Store(tmp_path / "store"), plan.jobs, set())
    scenes = [(g[0].environment.color is None, Path(g[0].mesh).name) for g in groups]
    # studio (an HDRI) sorts before white; within each world, box (cube.obj) before crate
    assert scenes == [(True, "cube.obj"), (True, "crate.obj"), (False, "cube.obj"), (False, "crate.obj")]
    assert all(len({(j.environment, j.mesh) for j in g}) == 1 for g in groups), "a group is one scene"


def _jobs(name: str, n: int) -> list[RenderJob]:
    return [RenderJob(f"{name}{i}", f"{name}.obj", EnvironmentRef()) for i in range(n)]


def _names(group: list[RenderJob] | None) -> str | None:
    return None if group is None else group[0].mesh.removesuffix(".obj")


def test_each_worker_gets_a_contiguous_share_balanced_by_jobs() -> None:
    groups = [_jobs("a", 4), _jobs("b", 4), _jobs("c", 2), _jobs("d", 2), _jobs("e", 4)]
    shares = Shares(groups, 2)
    assert [[_names(g) for g in share] for share in shares.shares] == [["a", "b"], ["c", "d", "e"]]
    assert [_names(shares.take(0)), _names(shares.take(1)), _names(shares.take(1))] == ["a", "c", "d"]


def test_an_idle_worker_takes_the_end_of_the_largest_share_left() -> None:
    shares = Shares([_jobs("a", 1), _jobs("b", 5), _jobs("c", 5), _jobs("d", 5)], 2)
    assert _names(shares.take(0)) == "a" and _names(shares.take(0)) == "b"
    assert _names(shares.take(0)) == "d", "worker 0's share is done: it takes what worker 1 would reach last"
    assert _names(shares.take(1)) == "c" and shares.take(1) is None and not shares


def test_a_dead_workers_jobs_go_back_to_the_front_of_its_share() -> None:
    shares = Shares([_jobs("a", 2), _jobs("b", 2)], 1)
    first = shares.take(0)
    shares.put_back(0, first[1:])
    assert [g[0].render_key for g in shares.shares[0]] == ["a1", "b0"]


def test_kept_gives_up_the_least_recently_used_beyond_its_count() -> None:
    kept: Kept[str, int] = Kept(max_count=2, max_cost=1e9, cost=float)
    for key, value in (("a", 1), ("b", 2), ("c", 3)):
        kept.add(key, value)
    assert kept.get("a") == 1  # a is now the most recent
    assert kept.evict() == [2] and "b" not in kept and list(kept.values()) == [3, 1]


def test_kept_gives_up_entries_beyond_its_cost_but_never_the_current_one() -> None:
    kept: Kept[str, int] = Kept(max_count=10, max_cost=5, cost=float)
    kept.add("a", 2)
    kept.add("b", 3)
    assert kept.evict() == []
    kept.add("huge", 100)
    assert kept.evict() == [2, 3] and list(kept.values()) == [100], "the most recent stays, however costly"
    assert kept.get("missing") is None and len(kept) == 1
