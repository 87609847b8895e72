"""The knobs a reproduction needs: [render] dither and world sampling, [model] resize_arithmetic,
[aggregate] drop_fragile. Each at its default leaves every key and the jobs file as they were."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sweep3d.core.errors import UserError
from sweep3d.spec.columns import DROP_FRAGILE_METADATA
from sweep3d.spec.models import RenderSpec
from sweep3d.stages.infer.handle import with_arithmetic
from sweep3d.stages.infer.models import LITE0_PREPROCESS, Preprocess, model_key, resize_uint8
from sweep3d.stages.render.worker_protocol import RenderSettings
from tests.helpers import TINY_SPEC, load_spec, plan_for, write_spec

PIXELS = {"resolution": 32}


def test_render_knobs_enter_the_key_only_off_their_defaults() -> None:
    base = RenderSpec().key_part(PIXELS)
    assert not {"dither", "world_sampling", "world_map_resolution"} & base.keys()
    assert RenderSpec(dither=1.0, world_sampling="automatic", world_map_resolution=2048).key_part(PIXELS) == base
    assert RenderSpec(dither=0.0).key_part(PIXELS) == {**base, "dither": 0.0}
    assert RenderSpec(world_sampling="none").key_part(PIXELS) == {**base, "world_sampling": "none"}
    assert RenderSpec(world_sampling="manual", world_map_resolution=256).key_part(PIXELS) == \
        {**base, "world_sampling": "manual", "world_map_resolution": 256}
    settings = RenderSettings.from_spec(RenderSpec(dither=0.5, world_sampling="manual"),
                                        type("F", (), {"size": 32, "crop": None})())
    assert (settings.dither, settings.world_sampling, settings.world_map_resolution) == (0.5, "manual", 1024)


def _plan(tmp_path: Path, extra: str = "", name: str = "a"):
    folder = tmp_path / name
    folder.mkdir()
    return plan_for(load_spec(write_spec(folder, TINY_SPEC + extra)), model_digest="m")


def test_a_spec_that_sets_nothing_keeps_its_keys_and_jobs_metadata(tmp_path: Path) -> None:
    plain = _plan(tmp_path)
    same = _plan(tmp_path, "\n[aggregate]\ndrop_fragile = false\n", "b")
    assert plain.jobs.key_column("render_key") == same.jobs.key_column("render_key")
    assert DROP_FRAGILE_METADATA not in plain.metadata(False)
    dropping = _plan(tmp_path, "\n[aggregate]\ndrop_fragile = true\n", "d")
    assert dropping.metadata(False)[DROP_FRAGILE_METADATA] == b"true"
    assert dropping.jobs.key_column("pred_key") == plain.jobs.key_column("pred_key")


def test_dither_changes_every_render_key(tmp_path: Path) -> None:
    plain = _plan(tmp_path)
    spec = (TINY_SPEC.replace("denoise = false", "denoise = false\ndither = 0.0"))
    folder = tmp_path / "dither"
    folder.mkdir()
    dithered = plan_for(load_spec(write_spec(folder, spec)), model_digest="m")
    assert not set(dithered.jobs.key_column("render_key")) & set(plain.jobs.key_column("render_key"))


def test_resize_arithmetic_is_in_the_model_key_only_when_not_float() -> None:
    assert "arithmetic" not in LITE0_PREPROCESS.key_part()
    eight = with_arithmetic(LITE0_PREPROCESS, "uint8", "m")
    assert eight.key_part() == {**LITE0_PREPROCESS.key_part(), "arithmetic": "uint8"}
    assert model_key("m", "w", eight) != model_key("m", "w", LITE0_PREPROCESS)
    assert with_arithmetic(LITE0_PREPROCESS, "float", "m") is LITE0_PREPROCESS
    with pytest.raises(UserError, match="resize_arithmetic"):
        with_arithmetic(object(), "uint8", "mine:factory")


def test_uint8_resize_rounds_to_8_bits_and_stays_within_a_level_or_two() -> None:
    rng = np.random.default_rng(0)
    images = (rng.integers(0, 256, size=(2, 40, 50, 3)) / 255.0).astype(np.float32)
    out = resize_uint8(images, (20, 25))
    assert out.shape == (2, 20, 25, 3) and out.dtype == np.float32
    assert np.allclose(out * 255, np.round(out * 255), atol=1e-4)  # on the 8-bit grid
    flat = np.full((1, 40, 50, 3), 0.5, np.float32)
    assert np.allclose(resize_uint8(flat, (20, 25)), 128 / 255)  # 0.5 quantised once


@pytest.mark.torch
def test_uint8_and_float_resizing_differ_by_little_but_differ() -> None:
    rng = np.random.default_rng(1)
    images = (rng.integers(0, 256, size=(1, 300, 300, 3)) / 255.0).astype(np.float32)
    floating = Preprocess(resize=256, crop=224)(images).numpy()
    eight = Preprocess(resize=256, crop=224, arithmetic="uint8")(images).numpy()
    step = 1 / 255 / 0.229  # one level after normalisation (the smallest std)
    assert floating.shape == eight.shape and not np.array_equal(floating, eight)
    assert np.abs(floating - eight).mean() < 2 * step


def test_aggregate_table_is_known_to_includes(tmp_path: Path) -> None:
    """``[aggregate]`` may come from an included file like the other tables."""
    folder = tmp_path / "inc"
    folder.mkdir()
    (folder / "common.toml").write_text("[aggregate]\ndrop_fragile = true\n")
    spec = write_spec(folder, 'include = ["common.toml"]\n' + TINY_SPEC)
    assert load_spec(spec).spec.aggregate.drop_fragile is True
