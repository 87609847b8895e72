"""The worked studies in examples/ load, plan and render as their README sections say."""

from __future__ import annotations

from io import BytesIO
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import REPO, load_spec, plan_for

MUG = REPO / "examples" / "mug_liquid" / "mug_liquid.toml"
needs_mug = pytest.mark.skipif(not Path("/usr/share/sweethome3d/furniture/KatorLegaz.sh3f").exists(),
                               reason="Sweet Home 3D's furniture is not installed (scripts/setup.sh installs it)")


@needs_mug
def test_the_mug_liquid_study_plans_every_liquid_at_every_viewpoint() -> None:
    loaded = load_spec(MUG)
    plan = plan_for(loaded)
    mixtures = {j.values["liquid"]["mixture"] for j in plan.jobs}
    assert len(plan.jobs) == 2 * 6 * 2 * 11 and len(mixtures) == 11
    empty = {j.render_key for j in plan.jobs if j.values["liquid"]["mixture"] == ""}
    assert len(empty) == 24, "the empty mug is the liquid control at its neutral value: one render per view"


@needs_mug
@pytest.mark.blender
def test_the_liquid_fills_the_mug_for_its_job_only(blender_scene, tmp_path: Path) -> None:
    from PIL import Image

    from sweep3d.assets.sources import materialise_mesh
    from sweep3d.stages.render.worker import render_job
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderJob

    loaded = load_spec(MUG)
    liquid = next(c.control for c in loaded.controls if c.id == "liquid")
    camera = next(c.control for c in loaded.controls if c.id == "camera")
    mesh = str(materialise_mesh(loaded.meshes["coffee mug"], tmp_path))

    def render(mixture: str) -> np.ndarray:
        controls = ((camera, camera.params({"elevation": 55.0})), (liquid, liquid.params({"mixture": mixture})))
        job = RenderJob(render_key="k", mesh=mesh, environment=EnvironmentRef(color=(1.0, 1.0, 1.0)),
                        blob=str(tmp_path / "x.png"), controls=controls)
        reply = render_job(blender_scene, job, keep_pixels=True)
        assert reply.ok and not reply.info.rebuilt, reply.error
        return np.asarray(Image.open(BytesIO(reply.png))).astype(int)

    empty, coffee, milk = render(""), render("0:0:3"), render("0:3:0")
    assert coffee.mean() < empty.mean() - 2, "black coffee shows inside the mug"
    assert milk.mean() > empty.mean() + 2 and not np.array_equal(milk, empty), "milk shows, and is lighter than the empty mug's shaded inside"
    assert np.array_equal(render(""), empty), "nothing of the liquid stays"
