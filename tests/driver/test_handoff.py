"""The in-memory image handoff between the postprocess and infer stages, and the plan status a
fresh store gets without finding each key's first job (fast lane: no Blender, no torch)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sweep3d.cache.store import Store
from sweep3d.driver.loop import stage_counts, unique_jobs
from sweep3d.stages.infer import InferStage, ModelHandle
from sweep3d.stages.postprocess import ImageHandoff, PostprocessStage
from sweep3d.stages.render import RenderStage
from tests.helpers import TINY_SPEC, plan_for, write_spec


def test_each_image_is_taken_once_and_the_oldest_goes_when_full() -> None:
    handoff = ImageHandoff(limit=2)
    pixels = [np.full((2, 2, 3), i, np.uint8) for i in range(3)]
    for key, image in zip("abc", pixels):
        handoff.put(key, image)
    assert handoff.take("a") is None  # forgotten: inference reads or makes it again
    assert np.array_equal(handoff.take("b"), pixels[1])
    assert handoff.take("b") is None
    assert np.array_equal(handoff.take("c"), pixels[2]) and len(handoff) == 0


def test_a_full_handoff_holds_the_stage_back_only_while_something_takes_images(monkeypatch) -> None:
    import threading
    import time

    from sweep3d.stages.postprocess import handoff as module

    handoff = ImageHandoff(limit=2)
    for key in "ab":
        handoff.put(key, np.zeros((2, 2, 3), np.uint8))
    started = time.monotonic()
    handoff.wait_for_room()  # full, but nothing has taken an image yet (a pass without inference)
    assert time.monotonic() - started < 0.5
    assert handoff.take("x") is None  # inference is taking images
    threading.Timer(0.3, handoff.take, ("a",)).start()
    started = time.monotonic()
    handoff.wait_for_room()
    assert time.monotonic() - started >= 0.25 and len(handoff) == 1
    monkeypatch.setattr(module, "STALL", 0.2)
    handoff.put("c", np.zeros((2, 2, 3), np.uint8))  # full again, and nothing takes any more
    started = time.monotonic()
    handoff.wait_for_room()
    assert 0.0 < time.monotonic() - started < 0.5 and len(handoff) == 2


def test_the_store_setting_decides_whether_the_stage_owns_blobs(tmp_path: Path) -> None:
    from tests.helpers import load_spec

    for store, owns in (("all", True), ("none", False)):
        folder = tmp_path / store
        folder.mkdir()
        spec = load_spec(write_spec(folder, TINY_SPEC + f'\n[postprocess]\nstore = "{store}"\n'))
        stage = PostprocessStage.for_spec(spec)
        assert stage.owns_blobs is owns and stage.store_images is owns


def test_a_fresh_store_counts_each_stage_s_distinct_keys(tmp_path: Path) -> None:
    from tests.helpers import load_spec

    spec = load_spec(write_spec(tmp_path, TINY_SPEC))
    plan = plan_for(spec, "0" * 40)
    store = Store(tmp_path / "store")
    model = ModelHandle.resolve(spec)
    for stage in (RenderStage(), PostprocessStage.for_spec(spec), InferStage(model)):
        needed, cached = stage_counts(stage, plan, store)
        assert (needed, cached) == (len(unique_jobs(stage, plan.jobs)), 0)
    assert plan.jobs.scenes() == {j.scene for j in plan.jobs} == {("box", "white"), ("box", "studio")}
