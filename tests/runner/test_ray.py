"""Rendering on a Ray cluster started on loopback: same results as the local pool, and a killed
actor's jobs are rendered again without duplicates."""

from __future__ import annotations

from pathlib import Path

import pytest

from sweep3d.cache.store import Store
from sweep3d.results import connect as connect_results
from sweep3d.runner.pipeline import run
from sweep3d.stages.render.render_stage import Executor
from tests.helpers import TINY_SPEC, load_spec, write_spec

ray = pytest.importorskip("ray")
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def local_cluster():
    """A one-node Ray cluster bound to 127.0.0.1 (tests never talk to another address)."""
    ray.init(_node_ip_address="127.0.0.1", include_dashboard=False, num_cpus=2, log_to_driver=False)
    yield
    ray.shutdown()


def _results(folder: Path) -> list[tuple]:
    return connect_results(Store(folder / "store"), "tiny").execute(
        "SELECT job, render_key, image_key, pred_key, top1_label, correct, round(loss, 3) FROM results ORDER BY job"
    ).fetchall()


def _visible_parts(folder: Path) -> dict[str, list[int]]:
    rows = connect_results(Store(folder / "store"), "tiny").execute(
        "SELECT render_key, parts, pixels, object_pixels FROM parts").fetchall()
    return {key: [p for p, n in zip(parts, pixels) if n >= 0.05 * total] for key, parts, pixels, total in rows}


def _truths(folder: Path) -> dict[str, tuple]:
    rows = connect_results(Store(folder / "store"), "tiny").execute(
        "SELECT truth_key, gt_x0, gt_y0, gt_x1, gt_y1, round(visible_fraction, 2) FROM truths").fetchall()
    return {row[0]: row[1:] for row in rows}


def _bytes(folder: Path) -> list[tuple]:
    """Every prediction's stored values, to the last bit."""
    return connect_results(Store(folder / "store"), "tiny").execute(
        "SELECT pred_key, label_prob, loss, topk_probs FROM predictions ORDER BY pred_key").fetchall()


@pytest.mark.parametrize("backend", ["", 'backend = "torch"\n'], ids=["stand-in", "torch"])
def test_ray_executor_gives_the_local_results(local_cluster, tmp_path: Path, monkeypatch, backend: str) -> None:
    """Torch infers on a Ray actor, ONNX Runtime standing in for it here as in a local run: the
    stand-in's rows are the local run's to the last bit (torch's on the actor were 2.1e-6 apart
    under the same keys)."""
    from sweep3d.stages.infer import ray_actor

    batches = []
    make_runner = ray_actor.remote_runner

    def counting_runner(*args):
        runner = make_runner(*args)
        return lambda images: batches.append(len(images)) or runner(images)

    monkeypatch.setattr(ray_actor, "remote_runner", counting_runner)
    ray_dir, local_dir = tmp_path / "ray", tmp_path / "local"
    for folder in (ray_dir, local_dir):
        folder.mkdir()
        # with the UV pass and the truth passes, whose blobs the driver writes as it writes the images
        write_spec(folder, TINY_SPEC.replace("[model]\n", "[model]\n" + backend)
                   + "\n[report]\npart_visibility = true\n\n[evaluator]\npasses = [\"mask\", \"depth\"]\n")
    on_ray = run(load_spec(ray_dir / "spec.toml"), executor=Executor("ray"))
    assert sum(batches) == (8 if backend else 0), "torch infers on the Ray actor, ONNX Runtime here"
    assert on_ray.failed == 0 and on_ray.outcome("render").computed == 4
    assert run(load_spec(local_dir / "spec.toml")).failed == 0
    assert _results(ray_dir) == _results(local_dir)
    if not backend:
        assert _bytes(ray_dir) == _bytes(local_dir)
    assert _visible_parts(ray_dir) == _visible_parts(local_dir) and len(_visible_parts(ray_dir)) == 4
    assert _truths(ray_dir) == _truths(local_dir) and len(_truths(ray_dir)) == 4
    store = Store(ray_dir / "store")
    assert all(store.blob_path(key, "mask.png").exists() and store.blob_path(key, "depth.npz").exists()
               for key in _truths(ray_dir))
    again = run(load_spec(ray_dir / "spec.toml"), executor=Executor("ray"))  # resumes from the store
    assert again.outcome("render").computed == 0


def test_a_killed_actor_loses_no_job_and_duplicates_none(local_cluster, tmp_path: Path) -> None:
    from sweep3d.stages.render.ray_pool import RayRenderPool
    from sweep3d.stages.render.render_stage import _groups
    from sweep3d.stages.render.worker_protocol import RenderSettings
    from tests.helpers import plan_for

    spec = write_spec(tmp_path, TINY_SPEC.replace("yaw = [0, 45]", "yaw = [0, 30, 60, 90, 120, 150]"))
    loaded = load_spec(spec)
    plan = plan_for(loaded, "m")
    store = Store(loaded.store)
    unique = list({j.render_key: j for j in plan.jobs}.values())  # blur variants share a render
    groups = [[job] for group in _groups(plan, store, unique, set()) for job in group]  # 12 one-job groups
    settings = RenderSettings(resolution=32, samples=1, denoise=False)
    seen = []
    with RayRenderPool(settings, workers=2) as pool:
        for result in pool.run(groups):
            seen.append(result)
            if len(seen) == 2:
                pool.kill_one()  # mid-run: its group in flight is lost and must be rendered again
    keys = [r.render_key for r in seen]
    assert len(keys) == len(set(keys)) == 12, "every job exactly once"
    assert all(r.ok for r in seen), [r.error for r in seen if not r.ok]
    assert all(store.blob_path(k).stat().st_size > 0 for k in keys)


def test_a_control_module_beside_the_spec_runs_on_ray_actors(local_cluster, tmp_path: Path, monkeypatch) -> None:
    """The actors get the control's code from the driver: no shared folder, no PYTHONPATH."""
    import textwrap

    from tests.helpers import SCENE_CONTROL

    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "rayslab.py").write_text(textwrap.dedent(SCENE_CONTROL))
    spec = write_spec(folder, TINY_SPEC.replace('type = "blur"\nsigma = [0.0, 1.5]', 'type = "rayslab:Slab"\nsize = [0.6]'))
    monkeypatch.chdir(tmp_path)
    result = run(load_spec(spec), executor=Executor("ray"))
    assert result.failed == 0 and result.outcome("render").computed == 4
