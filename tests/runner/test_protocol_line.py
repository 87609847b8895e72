"""Which protocol a run used, said in one line: renders that are the model's input, or full
frames the model resizes and crops itself (``[render] resolution``). ``plan`` and ``run`` print
it, the plan records it for the report. No Blender, no model."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.results.base_views import plan_protocol
from sweep3d.runner.pipeline import plan_spec, write_jobs
from sweep3d.spec.framing import Framing
from tests.helpers import TINY_SPEC, load_spec, write_spec

MODEL_VIEW = 'resolution = "model": renders are the model\'s input, the centre 224² of a 256² view, never resampled'
FIXED_224 = "resolution = 224: 224² renders, which the model resizes to 256² (upsampled 1.14×) and centre-crops to 224²"


def test_the_line_says_what_the_model_sees() -> None:
    assert Framing.of_model(256, 224).protocol((256, 224)) == MODEL_VIEW
    assert Framing.full(224).protocol((256, 224)) == FIXED_224
    assert Framing.full(512).protocol((256, 224)).endswith("resizes to 256² (downsampled 0.5×) and centre-crops to 224²")
    assert Framing.full(256).protocol((256, 224)).endswith("which the model centre-crops to 224² unresized")
    assert "the model's own preprocessing resizes and crops" in Framing.full(64).protocol(None)


@pytest.mark.parametrize("resolution, line", [('"model"', MODEL_VIEW), ("224", FIXED_224)])
def test_plan_prints_it_and_the_jobs_file_records_it_for_the_report(tmp_path: Path, resolution: str, line: str) -> None:
    spec = write_spec(tmp_path, TINY_SPEC.replace("resolution = 32", f"resolution = {resolution}"))
    printed = CliRunner().invoke(app, ["plan", str(spec)], terminal_width=200)
    assert printed.exit_code == 0, printed.output
    assert line in printed.output.splitlines()
    loaded = load_spec(spec)
    plan = plan_spec(loaded)
    assert plan.protocol == line
    write_jobs([plan], Store(loaded.store))
    assert plan_protocol(Store(loaded.store).jobs_path(loaded.name), plan.model) == line
    assert plan_protocol(Store(loaded.store).jobs_path(loaded.name), "another model") == ""

