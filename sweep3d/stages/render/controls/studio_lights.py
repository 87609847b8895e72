"""Studio lights a study varies: a sun (directional key) and a soft area light, each fixed in the
world or riding with the camera (angles: :mod:`sweep3d.stages.render.lights`)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from sweep3d.core import ControlParams
from sweep3d.stages.render.controls.rendered_control import RENDERED_CONTROLS, RenderedControl
from sweep3d.stages.render.lights import AreaLight, SunLight, light_colour
from sweep3d.stages.render.state import SceneState

#: ``temperature``: 0 is neutral white; otherwise a black-body tint in kelvin (below 1000 K, 1000 K's).
MAX_KELVIN = 40000.0


@RENDERED_CONTROLS.register("sun_light")
class SunLightControl(RenderedControl):
    """Adds a sun: ``strength`` is irradiance in W/m² (0 = none; π lights a white surface facing it
    as much as a plain world of strength 1 lights it from everywhere), ``angle`` its angular
    diameter in degrees (bigger: softer shadows), ``temperature`` (0 = white, else kelvin),
    ``azimuth``/``elevation`` in degrees and ``relative_to`` "world" (as the camera's angles) or
    "camera" (in the camera's frame: azimuth > 0 toward the image's right, elevation > 0 its top)."""

    order = 60
    frame_fields = {}
    periodic = {"azimuth": 360.0}
    neighbour_steps = {"strength": "light", "azimuth": "angle", "elevation": "angle"}

    class Params(ControlParams):
        strength: float = Field(0.0, ge=0.0, le=1e6)
        angle: float = Field(0.53, ge=0.0, le=180.0)
        temperature: float = Field(0.0, ge=0.0, le=MAX_KELVIN)
        azimuth: float = 45.0
        elevation: float = Field(45.0, ge=-90.0, le=90.0)
        relative_to: Literal["camera", "world"] = "world"

    def is_identity(self, values: dict[str, Any]) -> bool:
        return float(values.get("strength", 0.0)) == 0.0

    def apply(self, state: SceneState, params: Params) -> None:
        if params.strength > 0:
            state.lights.append(SunLight(light_colour(params.temperature), params.strength, params.angle,
                                         params.azimuth, params.elevation, params.relative_to))


@RENDERED_CONTROLS.register("area_light")
class AreaLightControl(RenderedControl):
    """Adds an area light facing the object's centre: ``watts`` its total power (0 = none; the
    same whatever its size, so ``size`` changes only how soft its shadows are), ``size`` its
    side or diameter (``shape`` "square" or "disk") and ``distance`` from the centre, both in
    object radii; ``temperature``, ``azimuth``, ``elevation`` and ``relative_to`` as for the sun.
    A white surface facing it gets about watts / (π · distance²) W/m²."""

    order = 60
    frame_fields = {}
    periodic = {"azimuth": 360.0}
    neighbour_steps = {"watts": "light", "azimuth": "angle", "elevation": "angle"}

    class Params(ControlParams):
        watts: float = Field(0.0, ge=0.0, le=1e7)
        size: float = Field(1.0, gt=0.0, le=1e4)
        shape: Literal["square", "disk"] = "square"
        distance: float = Field(4.0, gt=1.0, le=1e4)
        temperature: float = Field(0.0, ge=0.0, le=MAX_KELVIN)
        azimuth: float = 45.0
        elevation: float = Field(45.0, ge=-90.0, le=90.0)
        relative_to: Literal["camera", "world"] = "world"

    def is_identity(self, values: dict[str, Any]) -> bool:
        return float(values.get("watts", 0.0)) == 0.0

    def apply(self, state: SceneState, params: Params) -> None:
        if params.watts > 0:
            state.lights.append(AreaLight(light_colour(params.temperature), params.watts, params.size, params.shape,
                                          params.distance, params.azimuth, params.elevation, params.relative_to))
