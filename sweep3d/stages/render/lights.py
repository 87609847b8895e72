"""Sun and area lights as plain Python, and where a light stands for a given camera.

A light's ``azimuth``/``elevation`` mean what the camera's do when it is world-relative (azimuth
0 in front of the object, 90 on its +X side: the default camera's right). Camera-relative, the
same angles are taken in the camera's own frame: (0, 0) is the camera's position, positive
azimuth turns toward the image's right, positive elevation toward its top. The light then rides
with the camera, so it falls on the same side of the image whatever the camera control does.
Resolving the placement here, at pose time, keeps that true whatever order controls apply in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

if TYPE_CHECKING:
    from sweep3d.stages.render.state import SceneState

RelativeTo = Literal["camera", "world"]
SUN_DISTANCE = 10.0  # where a sun's object sits (only its direction matters), in object radii
WHITE = (1.0, 1.0, 1.0)


def kelvin_to_rgb(kelvin: float) -> tuple[float, float, float]:
    """Approximate linear RGB of a black body at ``kelvin`` (1000..40000), max component 1.

    Tanner Helland's sRGB fit, linearised: 6500 K comes out as (1, 0.99, 0.96), a faint warm tint
    under the Standard view transform, which is why the sun and area lights take 0 as white."""
    t = min(max(kelvin, 1000.0), 40000.0) / 100.0
    r = 255.0 if t <= 66 else 329.698727446 * (t - 60) ** -0.1332047592
    g = 99.4708025861 * math.log(t) - 161.1195681661 if t <= 66 else 288.1221695283 * (t - 60) ** -0.0755148492
    b = 255.0 if t >= 66 else (0.0 if t <= 19 else 138.5177312231 * math.log(t - 10) - 305.0447927307)
    rgb = [min(max(c / 255.0, 0.0), 1.0) ** 2.2 for c in (r, g, b)]  # sRGB-ish to linear
    peak = max(rgb)
    return tuple(c / peak for c in rgb)  # type: ignore[return-value]


def light_colour(temperature: float) -> tuple[float, float, float]:
    """Linear RGB of a light: 0 is neutral white (Blender's D65 working white, shown as white by
    the Standard view transform), else the black-body tint of :func:`kelvin_to_rgb`."""
    return WHITE if temperature == 0 else kelvin_to_rgb(temperature)


def direction(state: SceneState, azimuth: float, elevation: float, relative_to: RelativeTo) -> np.ndarray:
    """Unit vector from the object's centre toward a light at these angles (module docstring)."""
    az, el = math.radians(azimuth), math.radians(elevation)
    if relative_to == "world":
        return np.array([math.cos(el) * math.sin(az), -math.cos(el) * math.cos(az), math.sin(el)])
    _, right, up, forward = state.camera_basis()
    back = -forward  # from the object toward the camera
    return math.cos(el) * (math.cos(az) * back + math.sin(az) * right) + math.sin(el) * up


def facing(towards: np.ndarray) -> np.ndarray:
    """A rotation (3×3, columns x, y, z) whose z is ``towards``: Blender's suns and area lights
    shine along their local -Z, so this points them back along it, at the object."""
    z = towards / np.linalg.norm(towards)
    helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


@dataclass(frozen=True)
class SunLight:
    """A directional light: ``strength`` is irradiance in W/m² on a surface facing it."""

    rgb: tuple[float, float, float]
    strength: float
    angle: float  # angular diameter in degrees: 0 gives sharp shadows
    azimuth: float
    elevation: float
    relative_to: RelativeTo = "world"

    def matrix(self, state: SceneState) -> np.ndarray:
        """Its object's 4×4 world matrix for ``state``'s camera."""
        d = direction(state, self.azimuth, self.elevation, self.relative_to)
        return _placed(facing(d), state.object_location() + SUN_DISTANCE * d)


@dataclass(frozen=True)
class AreaLight:
    """A one-sided emitter facing the object's centre: ``watts`` is its total power (whatever
    its size), ``size`` its side or diameter and ``distance`` from the object's centre, both in
    object radii (the normalised object's: Blender metres)."""

    rgb: tuple[float, float, float]
    watts: float
    size: float
    shape: Literal["square", "disk"]
    distance: float
    azimuth: float
    elevation: float
    relative_to: RelativeTo = "world"

    def matrix(self, state: SceneState) -> np.ndarray:
        """Its object's 4×4 world matrix for ``state``'s camera."""
        d = direction(state, self.azimuth, self.elevation, self.relative_to)
        return _placed(facing(d), state.object_location() + self.distance * d)


def _placed(rotation: np.ndarray, location: np.ndarray) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3], matrix[:3, 3] = rotation, location
    return matrix
