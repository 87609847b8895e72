"""``sweep3d realism score --engine`` on the Ray executor: the kit's design replayed by Mitsuba
through the runner, rendered by Ray actors, stored as the verdicts a local score stores."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from sweep3d.cache.store import Store
from sweep3d.followups.realism.pick import pick
from sweep3d.followups.realism.score import score_engine
from sweep3d.results import VERDICTS
from sweep3d.stages.render import Executor
from tests.helpers import load_spec

pytestmark = [pytest.mark.slow, pytest.mark.blender, pytest.mark.torch]

ENGINE = "mitsuba"  # another renderer: its keys differ from the run's, so the replay renders
SAME = ("verdict_key", "source", "experiment", "job", "model", "valid", "correct", "top1_label", "image_key",
        "preprocess")


def _verdicts(folder: Path) -> list[dict]:
    return sorted(Store(folder / "store").table(VERDICTS).to_pylist(), key=lambda r: r["verdict_key"])


def _rendered(folder: Path, experiment: str) -> int:
    """How many renders the replaying spec's runs made (the runs table's render stage column)."""
    return sum(r["render_computed"] for r in Store(folder / "store").table("runs").to_pylist()
               if r["experiment"] == experiment)


def test_score_engine_on_ray_stores_the_local_verdicts(ray_cluster, tiny_copy: Path, tmp_path: Path) -> None:
    pytest.importorskip("mitsuba")
    spec = load_spec(tiny_copy / "spec.toml")
    kit = pick(spec, tiny_copy / "kit", per_object=2, seed=1)
    assert kit.jobs
    local = tmp_path / "local"
    shutil.copytree(tiny_copy, local)  # the kit's copy too: each score replays its own folder's design
    on_ray = score_engine(spec, ENGINE, kit=tiny_copy / "kit", executor=Executor("ray"))
    here = score_engine(load_spec(local / "spec.toml"), ENGINE, kit=local / "kit")
    replay = f"{spec.name}.engine-{ENGINE}"
    assert _rendered(tiny_copy, replay) == _rendered(local, replay) > 0  # the run's renders are Cycles'
    assert on_ray.verdicts == here.verdicts == len(kit.jobs) * len(spec.models)
    assert on_ray.agree == here.agree
    ray_rows, local_rows = _verdicts(tiny_copy), _verdicts(local)
    assert [tuple(r[c] for c in SAME) for r in ray_rows] == [tuple(r[c] for c in SAME) for r in local_rows]
    assert {r["source"] for r in ray_rows} == {f"engine:{ENGINE}"}
    assert [r["label_prob"] for r in ray_rows] == pytest.approx([r["label_prob"] for r in local_rows], abs=1e-4)
