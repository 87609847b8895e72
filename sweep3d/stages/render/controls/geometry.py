"""Pose, camera, placement and size of the object."""

from __future__ import annotations

from typing import Any

from pydantic import Field

from sweep3d.core import ControlParams
from sweep3d.stages.render.controls.rendered_control import RENDERED_CONTROLS, RenderedControl
from sweep3d.stages.render.state import SceneState, zoom_for_fill


@RENDERED_CONTROLS.register("orientation")
class Orientation(RenderedControl):
    """Rotates the object about its centre.

    Parameters (degrees, default range -180..180): ``yaw`` about the vertical axis, ``pitch``
    about the left-right axis, ``roll`` about the front-back axis.
    """

    order = 10
    frame_fields = {}
    periodic = {"yaw": 360.0, "pitch": 360.0, "roll": 360.0}
    neighbour_steps = {"yaw": "angle", "pitch": "angle", "roll": "angle"}

    class Params(ControlParams):
        yaw: float = 0.0
        pitch: float = 0.0
        roll: float = 0.0

    def apply(self, state: SceneState, params: Params) -> None:
        state.yaw, state.pitch, state.roll = params.yaw, params.pitch, params.roll


@RENDERED_CONTROLS.register("scale")
class Scale(RenderedControl):
    """Scales the object about its centre (``factor`` 1 = the normalised size, a unit bounding sphere)."""

    order = 10
    frame_fields = {"factor": "scale"}

    class Params(ControlParams):
        factor: float = Field(1.0, gt=0, le=1e6)

    def apply(self, state: SceneState, params: Params) -> None:
        state.scale = params.factor


@RENDERED_CONTROLS.register("camera")
class Camera(RenderedControl):
    """Moves the camera on a sphere around the object, looking at its centre.

    ``azimuth`` (degrees, 0 = in front, looking along +Y; 90 = on the object's +X side, the front
    camera's right: Blender's Right view), ``elevation`` (degrees above the object's centre,
    -90..90, 20 by default), ``zoom`` (1 = the object's bounding sphere spans about 78 % of the
    frame at 50 mm; 2 = twice as close) or ``fill`` (that share itself, exact at any focal length:
    it keys as the zoom it stands for), ``focal_length`` (mm, 36 mm sensor; the distance follows
    so framing stays, perspective changes) and ``fstop`` (aperture for depth of field, focused
    on the object's centre; 0 = pinhole).
    """

    order = 20
    frame_fields = {"azimuth": "azimuth", "elevation": "elevation", "zoom": "zoom", "fill": "fill",
                    "focal_length": "focal_length"}
    periodic = {"azimuth": 360.0}
    folds = {"fill": ("zoom", "focal_length")}
    neighbour_steps = {"azimuth": "angle", "elevation": "angle", "zoom": "closeness", "fill": "closeness"}

    class Params(ControlParams):
        azimuth: float = 0.0
        elevation: float = Field(20.0, ge=-90.0, le=90.0)
        zoom: float = Field(1.0, gt=0, le=1e6)
        #: Left out of a job's values unless given, so the keys and tables of zoom's jobs stay.
        fill: float | None = Field(None, gt=0, le=1000.0, exclude_if=lambda value: value is None)
        focal_length: float = Field(50.0, ge=1.0, le=5000.0)
        fstop: float = Field(0.0, ge=0.0, le=1000.0)

    def canonical(self, values: dict[str, Any]) -> dict[str, Any]:
        """A ``fill`` keys as the zoom it stands for (one render key for both); without one, as the base's."""
        out = super().canonical(values)
        fill = out.pop("fill", None)
        if fill is not None:
            focal = out.get("focal_length", self.Params.model_fields["focal_length"].default)
            out["zoom"] = float(zoom_for_fill(float(fill), float(focal)))
        return out

    def apply(self, state: SceneState, params: Params) -> None:
        state.azimuth, state.elevation = params.azimuth, params.elevation
        state.zoom, state.focal_length = params.zoom, params.focal_length
        state.fill = params.fill or 0.0
        state.fstop = params.fstop


@RENDERED_CONTROLS.register("position")
class Position(RenderedControl):
    """Places the object's centre at (``x``, ``y``) in the image: -1..1 spans the frame
    (fractions of the half-width and half-height; +x right, +y up)."""

    order = 30
    frame_fields = {"x": "frame_x", "y": "frame_y"}

    class Params(ControlParams):
        x: float = Field(0.0, ge=-100.0, le=100.0)
        y: float = Field(0.0, ge=-100.0, le=100.0)

    def apply(self, state: SceneState, params: Params) -> None:
        state.frame_x, state.frame_y = params.x, params.y


@RENDERED_CONTROLS.register("pin_to_ground")
class PinToGround(RenderedControl):
    """Sets the object down on a ground plane that catches its shadow (``enabled``), after
    rotation and scaling, so it rests on its lowest point as on a table."""

    order = 15
    frame_fields = {}  # the in-frame test ignores the ground

    class Params(ControlParams):
        enabled: bool = False

    def apply(self, state: SceneState, params: Params) -> None:
        state.pin_to_ground = params.enabled
