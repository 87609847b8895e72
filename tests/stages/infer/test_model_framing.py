"""``[render] resolution = "model"``: render exactly the model's input, and do not resample it.

The built-in EfficientNet-Lite0 resizes to 256 and centre-crops 224, so a model-framed render
is the centre 224² of a 256² frame. Renders are real Blender at 1 sample (the 256² frame costs
about 0.1 s); the model is the real pretrained one.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.core.pixels import decode_png
from sweep3d.driver.loop import run_stage
from sweep3d.driver.progress import RunProgress
from sweep3d.results import connect as connect_results
from sweep3d.spec.framing import Framing
from sweep3d.spec.models import RenderSpec
from sweep3d.stages.render import RenderStage, render_settings
from tests.helpers import TINY_SPEC, load_spec, plan_for, write_spec


def _spec(folder: Path, resolution: str, *, one_job: bool = False) -> Path:
    """The tiny spec at ``resolution`` (a TOML value), in the studio HDRI, yawed so edges show."""
    text = TINY_SPEC.replace("resolution = 32", f"resolution = {resolution}")
    if one_job:
        text = text.replace("yaw = [0, 45]", "yaw = 30").replace("sigma = [0.0, 1.5]", "sigma = 0.0")
    folder.mkdir(parents=True, exist_ok=True)
    return write_spec(folder, text)


def _with_resolution(loaded, resolution):
    render = loaded.spec.render.model_copy(update={"resolution": resolution})
    return dataclasses.replace(loaded, spec=loaded.spec.model_copy(update={"render": render}))


# -- keys and framing (no rendering) ---------------------------------------------------------


def test_model_resolution_resolves_to_the_models_resize_and_crop(tmp_path: Path) -> None:
    loaded = load_spec(_spec(tmp_path, '"model"'))
    plan = plan_for(loaded)
    assert plan.framing == Framing(256, 224, model=True)
    settings = render_settings(plan)
    assert settings.resolution == 256 and settings.crop == 224


def test_model_framing_and_full_frames_never_share_keys(tmp_path: Path) -> None:
    loaded = load_spec(_spec(tmp_path, '"model"'))
    plans = {res: plan_for(_with_resolution(loaded, res)) for res in ("model", 224, 256)}
    for other in (224, 256):
        for a, b in zip(plans["model"].jobs, plans[other].jobs):
            assert a.render_key != b.render_key and a.pred_key != b.pred_key
    assert plans["model"].model_digest != plans[224].model_digest  # preprocessing differs
    assert plans[224].model_digest == plans[256].model_digest  # same preprocessing, other pixels


def test_full_frame_render_keys_hash_as_before() -> None:
    """New settings at their neutral values stay out of the key: existing caches stay valid."""
    spec = RenderSpec(resolution=224)
    old = {"resolution": 224, "samples": 4, "denoise": True, "denoise_prefilter": "fast", "max_bounces": 8}
    assert spec.key_part(Framing(224, 224).key_part()) == old
    assert RenderSpec(seed=1).key_part({"resolution": 224})["seed"] == 1
    assert RenderSpec(adaptive_threshold=0.05).key_part({"resolution": 224})["adaptive_threshold"] == 0.05


@pytest.mark.parametrize("value", ['"full"', '"Model"', "7", "224.5", "true"])
def test_a_bad_resolution_is_one_line_naming_the_key(tmp_path: Path, value: str) -> None:
    spec = _spec(tmp_path, value)
    result = CliRunner().invoke(app, ["plan", str(spec)])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and f"{spec}: render.resolution: " in lines[0] and '"model"' in lines[0], result.output


# -- inference: no resampling ----------------------------------------------------------------


@pytest.mark.torch
def test_infer_only_normalises_model_framed_images(tmp_path: Path) -> None:
    """A model-framed 224² image reaches the model pixel for pixel; a full-frame one is resampled."""
    from sweep3d.stages.infer import ModelHandle

    loaded = load_spec(_spec(tmp_path, '"model"'))
    image = np.random.default_rng(0).random((1, 224, 224, 3), dtype=np.float32)
    framed = ModelHandle.resolve(loaded).classifier().preprocess(image).numpy()
    np.testing.assert_array_equal(framed, ((image - 0.5) / 0.5).transpose(0, 3, 1, 2))
    full = ModelHandle.resolve(_with_resolution(loaded, 224)).classifier().preprocess(image).numpy()
    assert full.shape == framed.shape and np.abs(full - framed).mean() > 0.1


# -- rendering ---------------------------------------------------------------------------------


def _render(loaded) -> tuple[np.ndarray, dict]:
    plan = plan_for(loaded)
    plan = dataclasses.replace(plan, jobs=[j for j in plan.jobs if j.environment == "studio"])
    store = Store(loaded.store)
    with store.lock():
        outcome = run_stage(RenderStage(), plan, store, RunProgress(None))
    assert outcome.failed == 0, outcome.errors
    return decode_png(store.blob_path(plan.jobs[0].render_key)), render_settings(plan)


@pytest.mark.blender
def test_a_model_framed_render_is_the_centre_crop_of_the_full_frame(tmp_path: Path) -> None:
    loaded = load_spec(_spec(tmp_path, '"model"', one_job=True))
    framed, settings = _render(loaded)
    full, _ = _render(_with_resolution(loaded, 256))
    assert framed.shape == (224, 224, 3) and full.shape == (256, 256, 3)
    assert settings.crop == 224

    def diff(dy: int, dx: int) -> float:
        return float(np.abs(framed - full[16 + dy : 240 + dy, 16 + dx : 240 + dx]).mean())

    # Same camera, pixel grid and per-pixel samples: equal up to a last bit here and there.
    assert diff(0, 0) < 0.002, diff(0, 0)
    # A frame off by one pixel in any direction is far from it.
    assert min(diff(dy, dx) for dy, dx in ((1, 0), (-1, 0), (0, 1), (0, -1))) > 5 * max(diff(0, 0), 1e-3)


@pytest.mark.slow
def test_a_model_framed_run_reports_sheets_and_benches(tmp_path: Path) -> None:
    """The whole pipeline at resolution = "model": 224² images in the store, the post control runs on
    them, the report and the contact sheet build, and the bench takes the setting as the spec's."""
    spec = _spec(tmp_path / "run", '"model"')
    text = spec.read_text().replace('[[environments]]\nname = "studio"\nhdri = "builtin:studio"\n', "")
    spec.write_text(text.replace("yaw = [0, 45]", "yaw = 30"))
    runner = CliRunner()
    result = runner.invoke(app, ["run", str(spec)])
    assert result.exit_code == 0, result.output
    store = Store(spec.parent / "store")
    con = connect_results(store, "tiny")
    assert con.execute("SELECT DISTINCT width, height FROM renders").fetchall() == [(224, 224)]
    assert con.execute("SELECT count(*) FROM results WHERE top1_label IS NOT NULL").fetchone()[0] == 2
    for key in store.keys("images"):
        assert decode_png(store.blob_path(key)).shape == (224, 224, 3)
    sheet = runner.invoke(app, ["sheet", str(spec)])
    assert sheet.exit_code == 0, sheet.output
    bench = runner.invoke(app, ["bench", str(spec), "--jobs", "1", "--reference-samples", "4", "--no-floor",
                                "--agreement", "0.5"], env={"COLUMNS": "200"})
    assert bench.exit_code == 0, bench.output
    spec_row = next(line for line in bench.output.splitlines() if "spec" in line and "│" in line)
    assert "1spp plain model" in spec_row, bench.output
    assert "recommended:" in bench.output



def test_bench_grid_repeats_no_setting_when_the_spec_renders_at_the_model_framing() -> None:
    import json

    from sweep3d.bench.measurement import Setting, default_settings

    for current in (Setting(4, "fast", resolution="model"), Setting(4, "fast")):
        spec_resolution = current.resolution or 224
        grid = default_settings(current, model_view=True, full_frame=224)
        effects = {json.dumps(s.render_update(spec_resolution), sort_keys=True) for s in grid}
        assert len(effects) == len(grid), [s.label() for s in grid]
        assert current in grid
        assert {s.render_update(spec_resolution)["resolution"] for s in grid} >= {224, "model"}
