"""Random specs for the planner's tests: built-in controls, and users' controls that each take a
slow path of the planner (an own ``apply``, an integer periodic angle, a validator that changes
numbers), under every policy."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from hypothesis import strategies as st
from pydantic import Field, field_validator

from sweep3d.core.control import ControlParams
from sweep3d.stages.postprocess.controls.post_control import PostControl
from sweep3d.stages.render.controls.rendered_control import RenderedControl
from sweep3d.stages.render.state import SceneState
from tests.helpers import spec_toml

# -- users' controls: each takes a slow path of the planner ------------------------------------


class Nudge(RenderedControl):
    """Moves the object by its own ``apply``: the planner cannot tell, so tests in-frame per job."""

    order = 35

    class Params(ControlParams):
        amount: float = 0.0

    def apply(self, state: SceneState, params: Params) -> None:
        state.frame_x += params.amount


class Turns(RenderedControl):
    """An integer angle (periodic in eighths): ints that key as wrapped floats."""

    periodic: ClassVar[dict[str, float]] = {"eighths": 8.0}
    frame_fields: ClassVar[dict[str, str]] = {}

    class Params(ControlParams):
        eighths: int = Field(0, ge=-100, le=100)

    def apply(self, state: SceneState, params: Params) -> None:
        pass


class Rounded(PostControl):
    """A validator that changes numbers: keyed as validated, one group per distinct value."""

    stochastic = True

    class Params(ControlParams):
        level: float = 0.0

        @field_validator("level")
        @classmethod
        def _round(cls, value: float) -> float:
            return round(value, 1)

    def apply(self, image: np.ndarray, params: Params, rng: np.random.Generator) -> np.ndarray:
        return image


HERE = "tests.helpers.plan_specs"






# -- random specs ------------------------------------------------------------------------------

numbers = st.floats(-400, 400, allow_nan=False).map(lambda x: round(x, 2))


@st.composite
def spaces(draw, low: float, high: float, log: bool = False, integer: bool = False) -> str:
    """A parameter's TOML: a fixed value, a list, or a range inside [low, high]."""
    kind = draw(st.sampled_from(["fixed", "list", "range"]))
    value = st.integers(int(low), int(high)) if integer else st.floats(low, high, allow_nan=False)
    if kind == "fixed":
        return repr(draw(value))
    if kind == "list":
        return "[" + ", ".join(repr(v) for v in draw(st.lists(value, min_size=1, max_size=3))) + "]"
    a, b = sorted(draw(st.lists(value, min_size=2, max_size=2, unique=True)))
    return f"{{ range = [{a!r}, {b!r}]{', log = true' if log and a > 0 else ''} }}"


CONTROLS = {
    "orientation": {"yaw": (-540, 540), "pitch": (-90, 90)},
    "camera": {"azimuth": (-180, 180), "elevation": (-90, 90), "zoom": (0.3, 3, True), "fill": (0.2, 3),
               "focal_length": (20, 90)},
    "position": {"x": (-2, 2), "y": (-2, 2)},
    "scale": {"factor": (0.2, 3)},
    "occlusion": {"coverage": (0, 1), "direction": (-360, 360)},
    "point_light": {"watts": (0, 50)},
    "sun_light": {"strength": (0, 5), "azimuth": (-360, 360)},
    "area_light": {"watts": (0, 50), "size": (0.5, 3)},
    "blur": {"sigma": (0, 3)},
    "noise": {"std": (0, 0.2)},
    f"{HERE}:Nudge": {"amount": (-3, 3)},
    f"{HERE}:Turns": {"eighths": (-20, 20, False, True)},
    f"{HERE}:Rounded": {"level": (-1, 1)},
}


@st.composite
def specs(draw) -> str:
    chosen = draw(st.lists(st.sampled_from(sorted(CONTROLS)), min_size=1, max_size=4, unique=True))
    blocks = []
    for name in chosen:
        params = draw(st.lists(st.sampled_from(sorted(CONTROLS[name])), min_size=1, unique=True))
        if {"zoom", "fill"} <= set(params):  # one or the other: fill sets the zoom
            params.remove("zoom")
        lines = [f'[[controls]]\ntype = "{name}"']
        for param in params:
            low, high, *flags = CONTROLS[name][param]
            lines.append(f"{param} = {draw(spaces(low, high, *flags))}")
        if draw(st.booleans()):
            lines.append(f'environments = ["{draw(st.sampled_from(["white", "grey"]))}"]')
        blocks.append("\n".join(lines))
    policy = draw(st.sampled_from([
        f'type = "grid"\nsamples_per_dim = {draw(st.integers(1, 3))}',
        f'type = "random"\nsamples = {draw(st.integers(1, 12))}',
        f'type = "sobol"\nsamples = {draw(st.integers(1, 8))}']))
    part_visibility = "\n[report]\npart_visibility = true\n" if draw(st.booleans()) else ""
    seed = draw(st.integers(0, 5))
    return spec_toml("columns", seed=seed, store=None, render={"resolution": 32, "samples": 1},
                     environments=("white", "grey"), body=f"""\
{part_visibility}
{chr(10).join(blocks)}

[policy]
{policy}
""")
