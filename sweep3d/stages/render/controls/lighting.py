"""Light and surroundings: point lights, HDRI rotation and strength, procedural sky, a plain
background colour, and the denoiser."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from sweep3d.core import ControlParams
from sweep3d.stages.render.controls.rendered_control import RENDERED_CONTROLS, RenderedControl
from sweep3d.stages.render.lights import kelvin_to_rgb
from sweep3d.stages.render.state import PointLight, SceneState, Sky


@RENDERED_CONTROLS.register("point_light")
class PointLightControl(RenderedControl):
    """Adds a point light: ``watts`` (0 = none), colour ``temperature`` in kelvin (6500 is a faint
    warm tint, see ``lights.kelvin_to_rgb``), ``distance`` from the origin in object radii,
    ``azimuth``/``elevation`` in degrees (as for the camera: azimuth 0 is in front). Use two ids
    for two lights."""

    order = 60
    frame_fields = {}
    periodic = {"azimuth": 360.0}
    neighbour_steps = {"watts": "light", "azimuth": "angle", "elevation": "angle"}

    class Params(ControlParams):
        watts: float = Field(0.0, ge=0.0, le=1e7)
        temperature: float = Field(6500.0, ge=1000.0, le=40000.0)
        distance: float = Field(4.0, gt=1.0, le=1e4)
        azimuth: float = 45.0
        elevation: float = Field(45.0, ge=-90.0, le=90.0)

    def is_identity(self, values: dict[str, Any]) -> bool:
        return float(values.get("watts", 0.0)) == 0.0

    def apply(self, state: SceneState, params: Params) -> None:
        if params.watts > 0:
            state.lights.append(PointLight(kelvin_to_rgb(params.temperature), params.watts,
                                           params.distance, params.azimuth, params.elevation))


@RENDERED_CONTROLS.register("hdri")
class Hdri(RenderedControl):
    """Turns the environment map about the vertical axis (``rotation``, degrees) and scales its
    light (``strength``, 1 = as the environment says). Rotating the world rebuilds Cycles'
    importance map (~0.75 s per distinct rotation), so orientation/camera are cheaper to vary."""

    order = 60
    frame_fields = {}
    periodic = {"rotation": 360.0}
    neighbour_steps = {"rotation": "hdri_rotation", "strength": "light"}

    class Params(ControlParams):
        rotation: float = 0.0
        strength: float = Field(1.0, gt=0.0, le=1e6)

    def apply(self, state: SceneState, params: Params) -> None:
        state.world_rotation, state.world_strength = params.rotation, params.strength


@RENDERED_CONTROLS.register("sky")
class SkyControl(RenderedControl):
    """Replaces the environment with Blender's procedural sky at a time of day: ``sun_elevation``
    (degrees above the horizon; below it is night) and ``sun_azimuth``; ``enabled`` switches it on."""

    order = 60
    frame_fields = {}
    periodic = {"sun_azimuth": 360.0}
    neighbour_steps = {"sun_elevation": "angle", "sun_azimuth": "angle", "strength": "light"}

    class Params(ControlParams):
        enabled: bool = False
        sun_elevation: float = Field(30.0, ge=-90.0, le=90.0)
        sun_azimuth: float = 0.0
        strength: float = Field(1.0, gt=0.0, le=1e6)

    def is_identity(self, values: dict[str, Any]) -> bool:
        return not values.get("enabled", False)

    def apply(self, state: SceneState, params: Params) -> None:
        if params.enabled:
            state.sky = Sky(params.sun_elevation, params.sun_azimuth, params.strength)


@RENDERED_CONTROLS.register("background")
class Background(RenderedControl):
    """Shows a plain ``color`` (hex, e.g. "#3366cc") behind the object instead of the
    environment, which still lights it; "" keeps the environment visible."""

    order = 60
    frame_fields = {}

    class Params(ControlParams):
        color: str = Field("", pattern=r"^(#[0-9a-fA-F]{6})?$")

    def canonical(self, values: dict[str, Any]) -> dict[str, Any]:
        return {**values, "color": str(values.get("color", "")).lower()}

    def apply(self, state: SceneState, params: Params) -> None:
        if params.color:
            h = params.color.lstrip("#")
            state.background = tuple(int(h[i : i + 2], 16) / 255.0 for i in (0, 2, 4))  # type: ignore[assignment]


@RENDERED_CONTROLS.register("denoiser")
class Denoiser(RenderedControl):
    """Switches OpenImageDenoise ``on`` or ``off`` per job (``mode``; "spec" = as render.denoise)."""

    order = 60
    frame_fields = {}

    class Params(ControlParams):
        mode: Literal["spec", "on", "off"] = "spec"

    def apply(self, state: SceneState, params: Params) -> None:
        state.denoise = None if params.mode == "spec" else params.mode == "on"
