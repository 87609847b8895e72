"""``sweep3d confirm`` on the Ray executor: its fresh twins rendered by Ray actors through the
runner, under the keys a local confirmation finds cached."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.followups.confirm.claims import boundary_claim
from sweep3d.followups.confirm.run import confirm
from sweep3d.spec.params import Range
from sweep3d.stages.render import Executor
from tests.helpers import load_spec, spec_toml, write_spec

pytestmark = [pytest.mark.slow, pytest.mark.blender, pytest.mark.torch]

SPEC = spec_toml("fresh", seed=3, model={"batch_size": 8}, body="""\
[[controls]]
type = "orientation"
yaw = { range = [-180, 180] }

[policy]
type = "random"
samples = 2
""")


def test_confirm_on_ray_renders_the_twins_a_local_one_finds_cached(ray_cluster, tmp_path: Path) -> None:
    spec = write_spec(tmp_path, SPEC)
    assert CliRunner().invoke(app, ["run", str(spec), "--no-report"]).exit_code == 0
    row = {"parameter": "orientation_yaw", "scope": "all", "object": None, "environment": None, "fails": "below",
           "boundary": 0.0, "values": 2, "boundary_low": -10.0, "boundary_high": 10.0}
    claim = boundary_claim(row, "orientation_yaw fails below 0", Range(-180.0, 180.0))
    loaded = load_spec(spec)
    on_ray = confirm(loaded, renders=2, claims=[claim], executor=Executor("ray"))
    assert on_ray.rendered == 2 and on_ray.failed == 0
    here = confirm(loaded, renders=2, claims=[claim])
    assert here.rendered == 0 and here.cached == 2
    assert here.confirmations[0].verdict == on_ray.confirmations[0].verdict
