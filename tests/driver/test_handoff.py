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
