"""A render stage kept open (``explain``'s rounds) renders plan after plan with the same Blender
worker, and stops it on close; a plain stage stops its workers after each plan, as a run does."""

from __future__ import annotations

from pathlib import Path

import pytest

from sweep3d.cache.store import Store
from sweep3d.driver.loop import run_stage
from sweep3d.driver.progress import RunProgress
from sweep3d.stages.render import LOCAL, RenderStage
from sweep3d.stages.render.child import live_children
from tests.helpers import load_spec, plan_for, spec_toml, write_spec

pytestmark = pytest.mark.blender


def _plan(folder: Path, yaw: float):
    """One 32 px job at ``yaw``: each plan's render is new; every plan shares the store and settings."""
    folder.mkdir()
    spec = spec_toml("kept", store=str(folder.parent / "store"),
                     body=f'[[controls]]\ntype = "orientation"\nyaw = [{yaw}]\n')
    return plan_for(load_spec(write_spec(folder, spec)), "stand-in")


def test_a_kept_stage_renders_each_plan_with_one_worker_and_stops_it_on_close(tmp_path: Path) -> None:
    first, second = _plan(tmp_path / "a", 0.0), _plan(tmp_path / "b", 30.0)
    store = Store(tmp_path / "store")
    kept = RenderStage(LOCAL, keep_open=True)
    with store.lock():
        assert run_stage(kept, first, store, RunProgress(None)).computed == 1
        pool = kept._warm[1]
        [worker] = pool.workers
        assert run_stage(kept, second, store, RunProgress(None)).computed == 1  # a new render ...
        assert kept._warm[1] is pool and pool.workers == [worker] and worker.process.is_alive()  # ... same worker
        kept.close()
        assert kept._warm is None and pool.workers == [] and not worker.process.is_alive()
        plain = RenderStage(LOCAL)
        third = _plan(tmp_path / "c", 60.0)
        assert run_stage(plain, third, store, RunProgress(None)).computed == 1
        assert plain._warm is None  # not kept: its worker was told to exit with the plan's last render
        [ending] = plain._ending
        assert ending.workers == []
        plain.close()  # waits until it has
        assert plain._ending == [] and live_children() == [] and not ending.scratch.exists()
    assert {j.render_key for p in (first, second, third) for j in p.jobs} <= store.keys("renders")
