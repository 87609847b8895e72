"""Post-processing on several cores: the same bytes for the same key, made in one process or in
worker processes (corruptions that draw from numpy's global generator, a blur, a user's control
beside the spec), handed on in plan order; a user control's error is one line naming it, and no
worker outlives the stage. Tiny synthetic renders, no Blender."""

from __future__ import annotations

import hashlib
import os
import textwrap
from pathlib import Path

import numpy as np
import pytest

from sweep3d.core import PluginError, from_uint8
from sweep3d.runner import builtin_catalogue
from sweep3d.spec import ControlInstance
from sweep3d.stages.postprocess import in_order
from sweep3d.stages.postprocess.apply import post_image
from sweep3d.stages.postprocess.in_order import InOrder
from sweep3d.stages.postprocess.post_workers import Task
from sweep3d.stages.render.child import live_children
from tests.helpers import load_spec, plan_for, spec_toml, write_spec

#: Corruptions that draw random numbers (noise, snow, spatter, elastic) and ones that do not, at 48².
CORRUPTIONS = ["gaussian_noise", "shot_noise", "impulse_noise", "speckle_noise", "snow", "spatter",
               "elastic_transform", "frost", "zoom_blur", "jpeg_compression"]


def texture(seed: int, side: int = 48) -> np.ndarray:
    """A render stand-in, uint8 (side, side, 3): smooth colour plus some noise, different per seed."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:side, 0:side] / (side - 1)
    image = np.stack([x, y, 0.5 + 0.4 * np.sin(7 * x * y + seed)], axis=-1) + rng.normal(0, 0.05, (side, side, 3))
    return (np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8)


def instance(type_name: str, control_id: str) -> ControlInstance:
    return ControlInstance(builtin_catalogue().controls.get(type_name)(control_id, type_name), {})


def tasks() -> list[Task]:
    """Three renders' images, each render's one after another as the plan orders them."""
    out = []
    for r in range(3):
        pixels = texture(r)
        for i, name in enumerate(CORRUPTIONS):
            values = {"c": {"name": name, "severity": 1 + (i + r) % 5}, "b": {"sigma": [0.0, 1.5][i % 2]}}
            key = hashlib.sha256(f"{r}/{name}".encode()).hexdigest()
            out.append(Task(key, f"render{r}", pixels, values, key))
    return out


def test_images_are_the_same_bytes_made_here_or_in_two_worker_processes() -> None:
    post = [instance("corruption", "c"), instance("blur", "b")]
    todo = tasks()
    here = InOrder(todo, post, workers=1, encode=True)
    alone = list(here)
    apart = InOrder(todo, post, workers=2, encode=True, start_seconds=0)
    spread = list(apart)
    assert here.pids == {os.getpid()}
    assert apart.pids and os.getpid() not in apart.pids, "the images were made in the worker processes"
    assert [t.image_key for t, _ in alone] == [t.image_key for t, _ in spread] == [t.image_key for t in todo]
    for (task, one), (_, two) in zip(alone, spread):
        reference, finite = post_image(from_uint8(task.pixels), post, task.values, task.image_key)
        assert np.array_equal(one.pixels, reference) and one.finite is finite
        assert np.array_equal(two.pixels, reference) and two.finite is finite, task.values
        assert one.png == two.png
    assert len({one.pixels.tobytes() for _, one in alone}) == len(todo), "every image differs from the others"
    assert live_children() == []


def test_workers_start_only_for_a_backlog_worth_their_start(monkeypatch) -> None:
    post = [instance("blur", "b")]
    todo = [Task(str(i), "r", texture(0), {"b": {"sigma": 1.0}}, f"{i:040x}") for i in range(20)]
    cheap = InOrder(todo, post, workers=2, encode=False)  # 20 blurs of 48²: milliseconds, not a second
    assert len(list(cheap)) == 20 and cheap.pids == {os.getpid()} and not cheap.started
    monkeypatch.setattr(in_order, "START_SECONDS", 1e-9)  # any backlog is worth it
    costly = InOrder(todo, post, workers=2, encode=False)
    made = list(costly)
    assert costly.started and [t.image_key for t, _ in made] == [t.image_key for t in todo]
    assert live_children() == []


def test_a_control_a_worker_could_not_import_keeps_the_images_here() -> None:
    from sweep3d.stages.postprocess import PostControl

    class Inverted(PostControl):  # as if written in a notebook: a worker runs no one's __main__
        def apply(self, image, params, rng):
            return 1.0 - image

    Inverted.__module__ = "__main__"
    post = [instance("blur", "b"), ControlInstance(Inverted("inv", "Inverted"), {})]
    todo = [Task(str(i), "r", texture(0), {"b": {"sigma": 1.0}, "inv": {}}, f"{i:040x}") for i in range(8)]
    here = InOrder(todo, post, workers=2, encode=False, start_seconds=0)
    assert len(list(here)) == 8 and here.pids == {os.getpid()} and here.pool is None


def test_a_slow_image_ahead_of_a_full_window_and_a_full_queue_stalls_nothing() -> None:
    """Every 48th image is slow: while a worker makes it, the other makes the rest of the window,
    and the reader's queue fills behind it; all of the window then goes at once."""
    import threading

    post = [instance("corruption", "c")]
    slow, fast = texture(1, 160), texture(2, 32)
    todo = [Task(i, "slow", slow, {"c": {"name": "zoom_blur", "severity": 5}}, f"{i:040x}") if i % 48 == 0 else
            Task(i, "fast", fast, {"c": {"name": "contrast", "severity": 1}}, f"{i:040x}") for i in range(800)]
    spread = InOrder(todo, post, workers=2, encode=False, start_seconds=0)
    out: list = []
    consumer = threading.Thread(target=lambda: out.extend(t.job for t, _ in spread), daemon=True)
    consumer.start()
    consumer.join(120)
    assert not consumer.is_alive(), f"stalled after {len(out)} of {len(todo)} images"
    assert out == list(range(800)) and os.getpid() not in spread.pids and live_children() == []


def test_no_worker_outlives_a_pass_stopped_midway() -> None:
    post = [instance("corruption", "c"), instance("blur", "b")]
    stopped = iter(InOrder(tasks(), post, workers=2, encode=False, start_seconds=0))
    next(stopped)
    assert live_children(), "the workers made the first image"
    stopped.close()  # the consumer went away (the pass failed elsewhere)
    assert live_children() == []

    class Cancelled(Exception):
        pass

    def cancelled_after_five():
        yield from tasks()[:5]
        raise Cancelled  # as the feed does when the pass stops (a stage failed, Ctrl-C)

    with pytest.raises(Cancelled):
        list(InOrder(cancelled_after_five(), post, workers=2, encode=False, start_seconds=0))
    assert live_children() == []


# -- the stage, with stand-in renders and a user's control beside the spec -----------------------
USER_CONTROL = '''
import numpy as np
from pydantic import Field
from sweep3d.core.control import ControlParams
from sweep3d.stages.postprocess import PostControl


class Speckle(PostControl):
    """Draws from numpy's global generator, seeded from the job's, as the corruptions do."""

    stochastic = True

    class Params(ControlParams):
        amount: float = Field(0.0, ge=0.0, le=1.0)

    def apply(self, image, params, rng):
        np.random.seed(int(rng.integers(0, 2**31 - 1)))
        return np.clip(image + params.amount * np.random.normal(0, 0.2, image.shape), 0, 1)


class Boom(PostControl):
    class Params(ControlParams):
        level: float = Field(0.0, ge=0.0, le=1.0)

    def apply(self, image, params, rng):
        if params.level > 0.5:
            raise ValueError("level too high for this image")
        return image
'''


def stage_spec(folder: Path, extra: str = "") -> Path:
    (folder / "spreadpost.py").write_text(textwrap.dedent(USER_CONTROL))
    return write_spec(folder, spec_toml("spread", seed=3, render={"resolution": 40, "samples": 1, "denoise": False},
                                        environments=("white", "grey"), body=f"""\
[[controls]]
type = "orientation"
yaw = [0, 30, 60]

[[controls]]
type = "corruption"
name = ["gaussian_noise", "impulse_noise", "snow", "motion_blur"]
severity = [0, 2, 5]

[[controls]]
type = "blur"
sigma = [0.0, 1.0]

[[controls]]
type = "spreadpost:Speckle"
amount = [0.0, 0.7]
{extra}
[postprocess]
store = "all"

[policy]
type = "grid"
"""))


def run_post(spec: Path, workers: int):
    """The stand-in render stage and the postprocess stage (with ``workers``) over ``spec``'s plan."""
    from sweep3d.cache.store import Store
    from sweep3d.driver.loop import run_stages
    from sweep3d.driver.progress import RunProgress
    from sweep3d.stages.postprocess import ImageHandoff, PostprocessStage

    plan = plan_for(load_spec(spec), "0" * 64)
    store = Store(spec.parent / "store")
    post = PostprocessStage(store_images=True, handoff=ImageHandoff(limit=10**6), workers=workers)
    with store.lock():
        outcomes = run_stages([textured_render(), post], plan, store, RunProgress(None), overlap=True)
    return outcomes, plan, store, post


def textured_render():
    """The render stage's bookkeeping with synthetic pixels: a texture per render key."""
    from sweep3d.cache.blobs import sha256_bytes
    from sweep3d.cache.store import DIGEST_COLUMN, atomic_write, utc_now
    from sweep3d.core.pixels import encode_png8
    from sweep3d.driver.loop import Computed
    from sweep3d.stages.render.render_stage import RenderStage

    class Stage(RenderStage):
        def compute(self, todo, plan, store):
            side = plan.framing.size
            for job in todo:
                data = encode_png8(texture(int(job.render_key[:8], 16), side))
                atomic_write(store.blob_path(job.render_key), data)
                yield Computed(job.render_key, {"render_key": job.render_key, "width": side, "height": side,
                                                "valid": True, "seconds": 0.0, "created_at": utc_now(),
                                                DIGEST_COLUMN: sha256_bytes(data)})

    return Stage()


def test_the_stage_stores_the_same_images_from_worker_processes_in_plan_order(tmp_path: Path, monkeypatch) -> None:
    one, two = tmp_path / "one", tmp_path / "two"
    one.mkdir(), two.mkdir()
    outcomes, plan, store_one, alone = run_post(stage_spec(one), workers=1)
    monkeypatch.setattr(in_order, "START_SECONDS", 0)  # the workers make every image
    outcomes_two, _, store_two, spread = run_post(stage_spec(two), workers=2)
    assert [o.computed for o in outcomes] == [o.computed for o in outcomes_two] and outcomes[1].computed > 50
    assert not any(o.failed for o in outcomes + outcomes_two)
    assert alone.spread.pids == {os.getpid()} and os.getpid() not in spread.spread.pids
    keys = sorted({j.image_key for j in plan.jobs if j.image_key != j.render_key})
    assert len(keys) == outcomes[1].computed
    for key in keys:
        assert store_one.blob_path(key).read_bytes() == store_two.blob_path(key).read_bytes()
        assert np.array_equal(alone.handoff.take(key), spread.handoff.take(key))
    digests = [store.connect().execute("SELECT image_key, sha256 FROM images ORDER BY image_key").fetchall()
               for store in (store_one, store_two)]
    assert digests[0] == digests[1] and len(digests[0]) == len(keys)
    assert live_children() == []


def test_a_user_control_failing_in_a_worker_is_one_line_naming_it(tmp_path: Path, monkeypatch) -> None:
    spec = stage_spec(tmp_path, '\n[[controls]]\ntype = "spreadpost:Boom"\nlevel = [0.0, 1.0]\n')
    monkeypatch.setattr(in_order, "START_SECONDS", 0)
    with pytest.raises(PluginError) as failed:
        run_post(spec, workers=2)
    message = str(failed.value)
    assert "\n" not in message and "spreadpost:Boom" in message and "level too high" in message
    assert live_children() == []
