"""``plan``'s render estimate is each engine's own (issue 45, item 6): Mitsuba's measured cost per
sample and per render, not Cycles' (each backend says where its figures come from)."""

from __future__ import annotations

from pathlib import Path

import pytest

from sweep3d.spec import RenderSpec
from sweep3d.stages.render import BACKENDS
from sweep3d.stages.render.estimate import estimate_render_seconds
from tests.helpers import TINY_SPEC, write_spec


@pytest.mark.parametrize("samples", [1, 4, 16, 256])
@pytest.mark.parametrize("side", [32, 224, 1024])
def test_mitsuba_is_estimated_from_its_own_costs(samples: int, side: int) -> None:
    cycles = RenderSpec(samples=samples)
    mitsuba = RenderSpec(samples=samples, engine="mitsuba")
    for truth, hidden in ((False, False), (True, True)):
        c, m = (estimate_render_seconds(r, side, truth, hidden) for r in (cycles, mitsuba))
        per_sample, per_render = BACKENDS.get("mitsuba").seconds_224
        cycles_sample, cycles_render = BACKENDS.get("cycles").seconds_224
        assert m != c
        assert m - c == pytest.approx((side / 224) ** 2 * ((per_sample - cycles_sample) * samples
                                                           + per_render - cycles_render))


def test_plan_estimates_a_mitsuba_spec_apart_from_the_same_cycles_spec(tmp_path: Path) -> None:
    pytest.importorskip("mitsuba")
    from sweep3d.api import Experiment

    for folder in ("c", "m"):
        (tmp_path / folder).mkdir()
    cycles = write_spec(tmp_path / "c", TINY_SPEC)
    mitsuba = write_spec(tmp_path / "m", TINY_SPEC.replace("[render]\n", '[render]\nengine = "mitsuba"\n', 1))
    seconds = {}
    for name, path in (("cycles", cycles), ("mitsuba", mitsuba)):
        status = Experiment(path).plan()
        [render] = [s for s in status.stages if s.stage.startswith("render")]
        seconds[name] = render.seconds
        spec = Experiment(path).spec
        assert render.seconds == pytest.approx(render.to_compute * estimate_render_seconds(
            spec.render, render.crop, bool(status.passes), False))
    assert seconds["mitsuba"] != seconds["cycles"] and min(seconds.values()) > 0
