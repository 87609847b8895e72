"""Truth passes beside a control whose ``edit`` changes what the scene held (issue 35, item 5).

Such an edit (a user's control changing the object's own material node values) makes the worker
rebuild its Blender scene; the rebuild used to come before the job's passes were read, so every
such job failed with "the worker rendered no truth passes", naming neither the control nor the
cause, while the run's findings still read as a clean summary. The jobs now render with their
passes, and a run with failed jobs says how many and why beside its findings.
"""

from __future__ import annotations

import io
import logging
from pathlib import Path

import pytest
from rich.console import Console
from typer.testing import CliRunner

from sweep3d.cache.store import Store, utc_now
from sweep3d.cli import app
from sweep3d.cli.output import print_run
from sweep3d.driver.outcome import StageOutcome
from sweep3d.results import connect as connect_results
from sweep3d.runner.pipeline import RunResult, write_jobs
from sweep3d.stages.render.render_stage import no_truth_error
from sweep3d.stages.render.worker_protocol import RenderInfo, RenderReply
from tests.helpers import CUBE_OBJ, TINY_SPEC, load_spec, plan_for, write_spec

PAINT = '''
from pydantic import Field

from sweep3d.plugins import ControlParams, RenderedControl


class Paint(RenderedControl):
    """Changes the object's own material in place: its node values."""

    class Params(ControlParams):
        shade: float = Field(0.0, ge=0.0, le=1.0)

    def edit(self, scene, params):
        if params.shade == 0:
            return
        for obj in scene.objects:
            for slot in obj.material_slots:
                if slot.material is not None and slot.material.node_tree is not None:
                    bsdf = slot.material.node_tree.nodes.get("Principled BSDF")
                    if bsdf is not None:
                        bsdf.inputs["Base Color"].default_value = (params.shade, 0.2, 0.2, 1)
'''
#: The tiny spec on one plain environment, each yaw painted and not, with the mask pass.
PAINTED = (TINY_SPEC.replace('[[environments]]\nname = "studio"\nhdri = "builtin:studio"\n\n', "")
           .replace("sigma = [0.0, 1.5]", "sigma = [0.0]")
           .replace("[policy]", '[[controls]]\ntype = "paints:Paint"\nshade = [0.0, 0.9]\n\n[policy]')
           + '\n[evaluator]\npasses = ["mask"]\n')


def painted_spec(folder: Path) -> Path:
    """:data:`PAINTED` with its control beside it and a red cube (a material its edit changes)."""
    (folder / "paints.py").write_text(PAINT)
    (folder / "cube.mtl").write_text("newmtl red\nKd 0.8 0.1 0.1\n")
    (folder / "cube.obj").write_text("mtllib cube.mtl\nusemtl red\n" + CUBE_OBJ)
    return write_spec(folder, PAINTED, cube=False)


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.torch
def test_jobs_whose_edit_changes_a_material_render_with_their_passes(tmp_path: Path, monkeypatch, caplog) -> None:
    spec = painted_spec(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    with caplog.at_level(logging.WARNING, logger="sweep3d.render"):
        result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output
    assert "rendered no truth passes" not in result.output and "error" not in result.output
    assert "changed what the scene already held (Material" in caplog.text  # the rebuild is still said
    con = connect_results(Store(tmp_path / "store"), "tiny")
    rows = con.execute("SELECT j.orientation_yaw, j.Paint_shade, g.visible_pixels FROM jobs j "
                       "JOIN ground_truth g USING (job) ORDER BY 1, 2").fetchall()
    assert len(rows) == 4 and all(pixels for _, _, pixels in rows), rows
    for (_, plain, pixels), (_, painted, painted_pixels) in zip(rows[::2], rows[1::2]):
        assert (plain, painted) == (0.0, 0.9) and painted_pixels == pixels, "paint does not move the mask"


# -- a run with failed jobs never reads as a clean one --------------------------------------------------
def _findings(tmp_path: Path, failed: int) -> str:
    """What ``run`` prints for the tiny plan with ``failed`` of its 8 jobs' renders failed (no
    prediction) and every other job predicted right."""
    plan = plan_for(load_spec(write_spec(tmp_path, TINY_SPEC)), "0" * 64)
    store = Store(plan.spec.store)
    jobs = list(plan.jobs)
    with store.lock():
        write_jobs(plan, store)
        store.append("predictions", [{"pred_key": j.pred_key, "image_key": j.image_key, "model": plan.model,
                                      "created_at": utc_now(), "valid": True, "correct": True, "top1_label": "carton",
                                      "loss": 0.1} for j in jobs[failed:]])
    error = "render {}: the worker rendered no truth passes: the edit() of control 'paints:Paint' changed ..."
    render = StageOutcome("render", total=8, computed=8 - failed, failed=failed,
                          errors=[error.format(j.render_key[:12]) for j in jobs[:failed]])
    infer = StageOutcome("infer", total=8, computed=8 - failed, skipped=failed)
    out = io.StringIO()
    print_run(Console(file=out, width=400), RunResult("r", plan, [plan], [render, infer], 1.0, store))
    return out.getvalue()


def test_a_run_with_failed_jobs_counts_and_names_them_beside_its_findings(tmp_path: Path) -> None:
    output = _findings(tmp_path, failed=2)
    [accuracy] = [line for line in output.splitlines() if line.startswith("top-1 accuracy")]
    assert accuracy.startswith("top-1 accuracy 100.0% (6 of 6; 2 jobs failed in the run and are not counted); "
                               "0 failures"), accuracy
    last = output.strip().splitlines()[-1]
    assert last == ("error: 2 of 8 jobs failed and are missing from the findings and the report; render: 2 failed "
                    "(the worker rendered no truth passes: the edit() of control 'paints:Paint' changed ...)"), last


def test_a_run_whose_every_job_failed_says_so_instead_of_nothing(tmp_path: Path) -> None:
    output = _findings(tmp_path, failed=8)
    assert "no accuracy: 8 jobs failed in the run and are not counted" in output
    last = output.strip().splitlines()[-1]
    assert last.startswith("error: all 8 jobs failed, so there are no findings and no report was written; render: "
                           "8 failed (the worker rendered no truth passes"), last
    assert "sweep3d run" not in last  # the same command would fail again: the cause is what to fix


def test_a_clean_run_prints_no_failure_line(tmp_path: Path) -> None:
    output = _findings(tmp_path, failed=0)
    assert "not counted" not in output and "error" not in output


def test_missing_passes_name_the_control_whose_edit_rebuilt_the_scene(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.syspath_prepend(str(tmp_path))
    plan = plan_for(load_spec(painted_spec(tmp_path)), "0" * 64)
    rebuilt = RenderReply("k", True, RenderInfo(1.0, True, 32, 32, rebuilt=("Material 'red'",)))
    assert no_truth_error(plan, rebuilt) == (
        "the worker rendered no truth passes: the edit() of control 'paints:Paint' changed what the scene held "
        "(Material 'red') and the scene was rebuilt before the passes were read")
    plain = RenderReply("k", True, RenderInfo(1.0, True, 32, 32))
    assert "a bug: please report it" in no_truth_error(plan, plain)
