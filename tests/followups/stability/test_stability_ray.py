"""``sweep3d stability`` on the Ray executor: the runner's session, no code of the check's own,
and the rows a local check stores (it renders nothing: its images are the run's)."""

from __future__ import annotations

import shutil
from pathlib import Path

from sweep3d.cache.store import Store
from sweep3d.followups.stability import check_stability
from sweep3d.stages.render import Executor
from tests.helpers import load_spec

SAME = ("stability_key", "pred_key", "image_key", "change", "seed", "base_correct", "base_margin", "correct", "margin")


def _rows(folder: Path) -> list[tuple]:
    return sorted(tuple(r[c] for c in SAME) for r in Store(folder / "store").table("stability").to_pylist())


def test_the_check_on_ray_stores_the_local_rows(ray_cluster, tiny_copy: Path, tmp_path: Path) -> None:
    local = tmp_path / "local"
    shutil.copytree(tiny_copy, local)
    on_ray = check_stability(load_spec(tiny_copy / "spec.toml"), sample=2, seed=3, executor=Executor("ray"), scene=False)
    here = check_stability(load_spec(local / "spec.toml"), sample=2, seed=3, scene=False)
    assert on_ray[0].computed == here[0].computed == 2
    assert _rows(tiny_copy) == _rows(local) and len(_rows(local)) == 6
