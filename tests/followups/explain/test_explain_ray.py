"""``sweep3d explain`` on the Ray executor: its probes rendered by Ray actors through the runner,
and the same nearest fixes as a local search."""

from __future__ import annotations

import shutil
from pathlib import Path

from sweep3d.followups.explain import explain_spec
from sweep3d.stages.render import Executor
from tests.helpers import load_spec


def test_explain_on_ray_finds_the_local_fixes(ray_cluster, tiny_copy: Path, tmp_path: Path) -> None:
    local = tmp_path / "local"
    shutil.copytree(tiny_copy, local)
    on_ray = explain_spec(load_spec(tiny_copy / "spec.toml"), budget=2, seed=1, executor=Executor("ray"))
    here = explain_spec(load_spec(local / "spec.toml"), budget=2, seed=1)
    assert on_ray.rendered == here.rendered and on_ray.probes == here.probes
    assert [(f.failure, f.fix) for f in on_ray.fixes] == [(f.failure, f.fix) for f in here.fixes]
