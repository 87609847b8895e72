"""The scene as plain Python: what rendered controls change and what Blender draws.

Rendered controls edit a :class:`SceneState`; :mod:`sweep3d.stages.render.cycles.scene` turns a state
into Blender objects. Keeping the state free of bpy makes controls testable without Blender
and lets the planner reason about geometry (for example, whether an object is in frame).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

if TYPE_CHECKING:
    from sweep3d.stages.render.lights import AreaLight, SunLight

SENSOR_WIDTH_MM = 36.0
FRAME_FILL = 0.8  # distance = 1 / (zoom · FRAME_FILL · sin(half fov)): the sphere spans ~78 % at 50 mm (docs/how-to/camera.md)
#: The :class:`SceneState` fields :func:`in_frame` reads.
FRAME_FIELDS = ("scale", "azimuth", "elevation", "zoom", "fill", "focal_length", "frame_x", "frame_y")
OCCLUDER_DEPTH = 0.5  # an occluder plate sits at this fraction of the way from camera to object
EDGE_TOLERANCE = 1e-9  # relative: states this close to the frame's edge are tested one by one


def zoom_for_fill(fill: Any, focal_length: Any) -> Any:
    """The zoom at which the object's bounding sphere spans ``fill`` of the frame's width, at this
    focal length (mm): the inverse of :func:`fill_of_zoom`, exact for any lens.

    With h the half field of view (tan h = 18 / f), the sphere's outline spans tan a / tan h of
    the frame where sin a = 0.8 · zoom · sin h (docs/how-to/camera.md); solved for zoom,
    zoom = fill · √(f² + 18²) / (0.8 · √(f² + (18 · fill)²)). Only +, ×, ÷ and √ (all correctly
    rounded), so floats and numpy arrays give the same bits: keys and the in-frame test agree.
    """
    half = SENSOR_WIDTH_MM / 2.0
    share = half * fill
    return fill * np.sqrt(focal_length * focal_length + half * half) / (
        FRAME_FILL * np.sqrt(focal_length * focal_length + share * share))


def fill_of_zoom(zoom: float, focal_length: float) -> float:
    """The share of the frame's width the bounding sphere's outline spans at this zoom and focal
    length (mm); 0 when the camera is inside the sphere (it then covers the whole view)."""
    half = math.atan(SENSOR_WIDTH_MM / (2.0 * focal_length))
    sine = FRAME_FILL * zoom * math.sin(half)
    return math.tan(math.asin(sine)) / math.tan(half) if sine < 1.0 else 0.0


@dataclass(frozen=True)
class PointLight:
    """A point light placed on a sphere around the object (angles as for the camera)."""

    rgb: tuple[float, float, float]
    watts: float
    distance: float  # in object radii
    azimuth: float
    elevation: float
    radius: float = 0.1  # soft-shadow size, in object radii

    def position(self) -> np.ndarray:
        az, el = math.radians(self.azimuth), math.radians(self.elevation)
        return self.distance * np.array([math.cos(el) * math.sin(az), -math.cos(el) * math.cos(az), math.sin(el)])


@dataclass(frozen=True)
class Occluder:
    """A flat grey plate between camera and object covering part of the object's extent."""

    coverage: float  # 0..1 of the object's diameter, from the ``direction`` side
    direction: float  # degrees in the image plane: 0 = from the right, 90 = from the top
    grey: float = 0.5


@dataclass(frozen=True)
class Sky:
    """Blender's procedural sky (Nishita) lit by a sun at this elevation and azimuth (degrees)."""

    sun_elevation: float
    sun_azimuth: float
    strength: float = 1.0


@dataclass
class SceneState:
    """Neutral values here are the neutral defaults of the built-in controls.

    The object is normalised to a bounding sphere of radius 1 at the origin, front facing -Y.
    Angles are degrees.
    """

    yaw: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0
    scale: float = 1.0
    azimuth: float = 0.0
    elevation: float = 20.0
    zoom: float = 1.0
    fill: float = 0.0  # > 0: the bounding sphere's share of the frame's width, which sets the zoom
    focal_length: float = 50.0
    frame_x: float = 0.0  # object centre in the image, as a fraction of the half-width (+ right)
    frame_y: float = 0.0  # ... of the half-height (+ up)
    fstop: float = 0.0  # 0 = pinhole camera (no depth of field)
    pin_to_ground: bool = False
    occluder: Occluder | None = None
    skin: str = "original"  # or a procedural skin name, or "image"
    skin_scale: float = 1.0
    skin_image: str | None = None
    denoise: bool | None = None  # None = as the render settings say
    lights: list[PointLight | SunLight | AreaLight] = field(default_factory=list)
    sky: Sky | None = None
    world_rotation: float = 0.0  # degrees about the vertical axis
    world_strength: float = 1.0  # multiplies the environment's strength
    background: tuple[float, float, float] | None = None  # a plain colour behind the object
    #: Principled BSDF values per material for this job: (material name as the file names it, "" for
    #: all; sorted (input, value) pairs), applied in order (see ``material_edits``).
    material_edits: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()

    def half_fov(self) -> float:
        """Half the camera's field of view in radians (square sensor)."""
        return math.atan(SENSOR_WIDTH_MM / (2.0 * self.focal_length))

    def framing_zoom(self) -> float:
        """``zoom``, or the zoom ``fill`` stands for at this focal length when it is set."""
        return float(zoom_for_fill(self.fill, self.focal_length)) if self.fill > 0 else self.zoom

    def camera_distance(self) -> float:
        """Distance from which a unit sphere (scale 1) is seen under an angle whose sine is ``FRAME_FILL``
        times the half field of view's (its outline spans tan(asin(0.8 sin h)) / tan h of the
        frame: 78 % at zoom 1 and 50 mm; docs/how-to/camera.md)."""
        return 1.0 / (self.framing_zoom() * FRAME_FILL * math.sin(self.half_fov()))

    def camera_basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Camera position, right, up and forward unit vectors (world space, float64, shape (3,)).

        Up is the derivative of the position along elevation, so the basis stays well defined
        at elevation ±90° (no gimbal lock).
        """
        az, el = math.radians(self.azimuth), math.radians(self.elevation)
        d = self.camera_distance()
        position = d * np.array([math.cos(el) * math.sin(az), -math.cos(el) * math.cos(az), math.sin(el)])
        forward = -position / d
        up = np.array([-math.sin(el) * math.sin(az), math.sin(el) * math.cos(az), math.cos(el)])
        right = np.cross(forward, up)
        return position, right, up, forward

    def object_location(self) -> np.ndarray:
        """Where the object's centre goes so it appears at (frame_x, frame_y) in the image."""
        _, right, up, _ = self.camera_basis()
        reach = self.camera_distance() * math.tan(self.half_fov())
        return reach * (self.frame_x * right + self.frame_y * up)


def in_frame(state: SceneState) -> bool:
    """False when the object's bounding sphere lies wholly outside the camera's view.

    Uses the same geometry the renderer will: the sphere of radius ``scale`` at
    :meth:`SceneState.object_location`, against the four side planes of the (square) frustum
    and the plane of the camera.

    The frame is always the full one, also with ``resolution = "model"``, where only its centre
    crop is rendered: position, zoom and occlusion keep their meaning, and an object that lies
    only in the cropped-away margin is rendered but not seen, as the model never saw that
    margin before either (its preprocessing cropped it).
    """
    position, right, up, forward = state.camera_basis()
    rel = state.object_location() - position
    x, y, z = float(np.dot(rel, right)), float(np.dot(rel, up)), float(np.dot(rel, forward))
    radius = state.scale
    if z < -radius:
        return False
    half = state.half_fov()
    cos_a, sin_a = math.cos(half), math.sin(half)
    return all(side * cos_a - z * sin_a <= radius for side in (x, -x, y, -y))


def in_frame_many(fields: Mapping[str, np.ndarray | float], n: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`in_frame` of ``n`` states at once, from the :data:`FRAME_FIELDS` as arrays (a
    missing field keeps :class:`SceneState`'s default).

    Returns:
        (in frame, unsure): ``unsure`` marks states within rounding of the frame's edge, where
        numpy's sines may round differently from the scalar test: the caller tests those with
        :func:`in_frame`, so the answer is the scalar test's for every state.
    """
    neutral = SceneState()
    f = {name: np.broadcast_to(np.asarray(fields.get(name, getattr(neutral, name)), dtype=np.float64), (n,))
         for name in FRAME_FIELDS}
    half = np.arctan(SENSOR_WIDTH_MM / (2.0 * f["focal_length"]))
    fill = f["fill"]
    zoom = np.where(fill > 0, zoom_for_fill(np.where(fill > 0, fill, 1.0), f["focal_length"]), f["zoom"])
    distance = 1.0 / (zoom * FRAME_FILL * np.sin(half))
    az, el = np.radians(f["azimuth"]), np.radians(f["elevation"])
    forward = np.stack([-np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), -np.sin(el)])
    up = np.stack([-np.sin(el) * np.sin(az), np.sin(el) * np.cos(az), np.cos(el)])
    right = np.cross(forward, up, axis=0)
    reach = distance * np.tan(half)
    rel = reach * (f["frame_x"] * right + f["frame_y"] * up) + distance * forward  # object - camera
    x, y, z = (rel * right).sum(0), (rel * up).sum(0), (rel * forward).sum(0)
    radius = f["scale"]
    behind = z + radius  # < 0: wholly behind the camera
    outside = np.maximum(np.abs(x), np.abs(y)) * np.cos(half) - z * np.sin(half) - radius  # > 0: beyond a side
    inside = (behind >= 0) & (outside <= 0)
    tolerance = EDGE_TOLERANCE * (np.abs(x) + np.abs(y) + np.abs(z) + radius + distance)
    unsure = (np.abs(behind) <= tolerance) | (np.abs(outside) <= tolerance)
    unsure |= ~(np.isfinite(behind) & np.isfinite(outside))
    return inside & ~unsure, unsure
