"""An occluder that a user's control adds in ``edit``: the visible fraction counts it as one (the
README's "visible pixels over those the object covers with no occluder"), alone and beside the
built-in plate, and a job it hides wholly is reported fully occluded, not out of frame.

Real renders of a cube at 48×48, 1 sample, through the render stage (10 jobs, about 3 s). The
unoccluded silhouette is the mask of the job with no occluder at all (the cube lies well inside
the frame).
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import pytest

from sweep3d.cache.blobs import load_pass
from sweep3d.cache.hashing import digest
from sweep3d.cache.store import Store
from sweep3d.driver.loop import run_stage
from sweep3d.driver.progress import RunProgress
from sweep3d.results import connect as connect_results
from sweep3d.runner.pipeline import write_jobs
from sweep3d.stages.render import RenderStage
from sweep3d.stages.render.render_keys import truth_keys
from tests.helpers import load_spec, plan_for, spec_toml, write_spec

WALL = '''\
from pydantic import Field

from sweep3d.plugins import ControlParams, RenderedControl


class Wall(RenderedControl):
    """A thin box halfway between the camera and the object, covering the object's bounding disc
    from the left up to ``cover`` of its width (1: all of it); scenery, not part of the object."""

    class Params(ControlParams):
        cover: float = Field(0.0, ge=0.0, le=1.0)

    def edit(self, scene, params):
        if params.cover == 0:
            return
        bpy = scene.bpy
        centre = scene.camera.matrix_world.inverted() @ scene.pose.matrix_world.translation  # camera frame
        x, y, z = centre / 2  # halfway, where the object's bounding disc has half its radius
        radius = scene.pose.scale[0] / 2
        right = x + radius * (2 * params.cover - 1)
        corners = [(a, b, z + dz) for a in (x - 10 * radius, right) for b in (y - 10 * radius, y + 10 * radius)
                   for dz in (-0.01, 0.01)]
        faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
        mesh = bpy.data.meshes.new("wall")
        mesh.from_pydata(corners, [], faces)
        scene.add(bpy.data.objects.new("wall", mesh), parent=scene.camera)  # in the camera's frame
'''

SPEC = spec_toml("wall", seed=1, render={"resolution": 48, "samples": 1, "denoise": False}, body="""\
[[controls]]
type = "walls:Wall"
cover = [0.0, 0.3, 0.8, 1.0]

[[controls]]
type = "occlusion"
coverage = [0.0, 0.5]

[[controls]]
type = "position"
x = [0.0, 1.5, 1.7]

[policy]
type = "table"
file = "design.csv"

[evaluator]
passes = ["mask"]
""")
#: (wall cover, plate coverage, x): the object centred, then at the frame's right edge (a sliver
#: at 1.5; at 1.7 its bounding sphere is in frame, no pixel of the cube is).
JOBS = [(0.0, 0.0, 0.0), (0.0, 0.5, 0.0), (0.3, 0.0, 0.0), (0.3, 0.5, 0.0), (0.8, 0.0, 0.0), (0.8, 0.5, 0.0),
        (1.0, 0.0, 0.0), (0.0, 0.0, 1.5), (1.0, 0.0, 1.5), (0.0, 0.0, 1.7)]


def planned(folder: Path):
    """The spec's plan of :data:`JOBS` in ``folder`` (the control's file beside it), with a
    stand-in model digest."""
    (folder / "walls.py").write_text(WALL)
    (folder / "design.csv").write_text("object,environment,Wall_cover,occlusion_coverage,position_x\n"
                                       + "".join(f"box,white,{c},{o},{x}\n" for c, o, x in JOBS))
    return plan_for(load_spec(write_spec(folder, SPEC)), "0" * 64)


@pytest.fixture(scope="module")
def walled(tmp_path_factory) -> tuple[dict[tuple[float, float, float], dict], Store]:
    """The rendered jobs' ground truth with their truth rows' ``framed_pixels`` and their masks,
    by (cover, coverage, x), and the store (with a stand-in model's answers)."""
    plan = planned(tmp_path_factory.mktemp("walled"))
    store = Store(plan.spec.store)
    with store.lock():
        outcome = run_stage(RenderStage(), plan, store, RunProgress(None))
        write_jobs(plan, store)
        _predict(store, plan)
    assert outcome.failed == 0, outcome.errors
    con = connect_results(store, "wall")
    cursor = con.execute("SELECT j.Wall_cover, j.occlusion_coverage, j.position_x, j.in_frame, g.*, t.framed_pixels "
                         "FROM jobs j JOIN ground_truth g USING (job) JOIN truths t ON t.truth_key = g.truth_key")
    names = [d[0] for d in cursor.description]
    rows = {(r[0], r[1], r[2]): dict(zip(names, r)) for r in cursor.fetchall()}
    assert sorted(rows) == sorted(JOBS)  # every job in frame for the planner, and rendered
    for row in rows.values():
        row["mask"] = load_pass(store, row["truth_key"], "mask")
    return rows, store


def _predict(store: Store, plan) -> None:
    """A stand-in model's answer per job, so that ``results`` and ``not_evaluable`` exist."""
    now = datetime.now(timezone.utc).replace(tzinfo=None)
    store.append("predictions", [{"pred_key": j.pred_key, "image_key": j.image_key, "model": "m", "created_at": now,
                                  "valid": True, "correct": True, "top1_label": "carton"} for j in plan.jobs])


@pytest.mark.blender
def test_the_visible_fraction_counts_what_an_edit_adds_as_an_occluder(walled) -> None:
    rows, _ = walled
    clear = rows[0.0, 0.0, 0.0]
    unoccluded = int(clear["mask"].sum())  # the silhouette: nothing hides the cube, all of it in frame
    assert clear["visible_fraction"] == pytest.approx(1.0) and unoccluded > 150
    for (_, _, x), row in rows.items():
        visible = int(row["mask"].sum())
        assert row["visible_pixels"] == visible
        if x == 0.0:  # in the middle of the frame: only occluders hide it
            assert row["visible_fraction"] == pytest.approx(visible / unoccluded, abs=0.02), row
            assert row["framed_pixels"] == pytest.approx(unoccluded, rel=0.05), row
    sliver = rows[0.8, 0.0, 0.0]  # the wall leaves a sliver: less than min_visible, so not evaluable
    assert 0 < sliver["visible_pixels"] and sliver["visible_fraction"] < 0.1 and sliver["evaluable"] is False
    partial = rows[0.3, 0.0, 0.0]
    assert 0.2 < partial["visible_fraction"] < 0.9 and partial["evaluable"] is True


@pytest.mark.blender
def test_the_plate_and_an_edits_occluder_both_hide_the_object(walled) -> None:
    rows, _ = walled
    unoccluded = int(rows[0.0, 0.0, 0.0]["mask"].sum())
    plate, wall, both = rows[0.0, 0.5, 0.0], rows[0.3, 0.0, 0.0], rows[0.3, 0.5, 0.0]
    assert 0 < both["visible_pixels"] < min(plate["visible_pixels"], wall["visible_pixels"])
    assert both["visible_fraction"] == pytest.approx(both["visible_pixels"] / unoccluded, abs=0.02)
    assert both["silhouette_pixels"] == pytest.approx(unoccluded, rel=0.05)  # neither is in the silhouette


@pytest.mark.blender
def test_an_unseen_object_in_frame_is_fully_occluded_or_out_of_frame_as_it_is(walled) -> None:
    rows, store = walled
    edge, clipped = rows[0.0, 0.0, 1.5], rows[0.0, 0.0, 1.7]
    assert 0 < edge["visible_pixels"] == pytest.approx(edge["framed_pixels"], abs=2)  # the frame's edge alone
    assert clipped["visible_pixels"] == clipped["framed_pixels"] == 0 and clipped["silhouette_pixels"] > 0
    occluded = [key for key, row in rows.items() if row["visible_pixels"] == 0 and row["framed_pixels"] > 0]
    assert sorted(occluded) == [(0.8, 0.5, 0.0), (1.0, 0.0, 0.0), (1.0, 0.0, 1.5)]
    assert all(r["in_frame"] and r["visible_fraction"] == 0.0 and r["evaluable"] is False for r in rows.values()
               if r["visible_pixels"] == 0)
    reasons = dict(connect_results(store, "wall").execute("SELECT reason, n FROM not_evaluable").fetchall())
    assert reasons == {"fully occluded": 3, "out of frame": 1, "hidden": 2}  # hidden: the two slivers


def test_only_the_jobs_an_edit_acts_on_get_new_truth_keys(tmp_path: Path) -> None:
    """Truth rows of renders without an edit stay valid (their keys are as before); those with one
    are made again."""
    for job in planned(tmp_path).jobs:
        before = digest({"stage": "truth", "v": 1, "passes": ["mask"], "render": job.render_key})
        assert truth_keys([job.render_key], ["mask"]) == [before]
        assert (job.truth_key != before) == (job.values["Wall"]["cover"] > 0), job.values
