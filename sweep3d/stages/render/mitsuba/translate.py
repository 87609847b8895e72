"""A job as Mitsuba's scene description (plain dicts and numpy; no Mitsuba import here).

Blender's conventions, translated once here so the two engines agree:

- **World map.** Cycles looks an equirectangular map up at u = ½ − atan2(y, x) / 2π, v = the
  elevation, after the Mapping node turns the direction about Z by the world's rotation;
  Mitsuba's ``envmap`` looks up u = atan2(x', −z') / 2π, v = acos(y') / π in its local frame.
  The two agree when local = (y, z, x) of the turned direction: :func:`envmap_to_world`
  (tests/stages/render/test_mitsuba.py renders a marked map in both engines).
  Strength is the map's ``scale``.
- **Camera.** Blender's camera looks down its −Z with Y up and a horizontal 36 mm sensor:
  Mitsuba's ``perspective`` with ``fov_axis = "x"`` and ``look_at`` along the same basis.
- **Lights.** A point light of P W has intensity P / 4π W/sr; a sun's strength is irradiance;
  an area light of P W (``normalize``) has radiance P / (π · area), emitted toward the object.
- **Object.** The normalising transform (unit bounding sphere at the origin) under the pose
  (Euler XYZ: yaw about Z after roll about Y after pitch about X), scale and location.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sweep3d.stages.render.lights import AreaLight, SunLight, direction, facing
from sweep3d.stages.render.state import OCCLUDER_DEPTH, SENSOR_WIDTH_MM, PointLight, SceneState

#: The least ``specular`` given to Mitsuba's principled BSDF (Blender's IOR 1 reflects nothing; Mitsuba's
#: needs an index of refraction above 1).
MIN_SPECULAR = 1e-3


def rotation_z(degrees: float) -> np.ndarray:
    """4×4 rotation about +Z."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    return m


def envmap_to_world(rotation: float) -> np.ndarray:
    """The ``envmap``'s to_world that shows an HDRI as Blender's world does, turned by ``rotation``
    degrees about Z (the Mapping node's rotation; module docstring)."""
    world_to_local = np.eye(4)
    world_to_local[:3, :3] = [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]
    return np.linalg.inv(world_to_local @ rotation_z(rotation))


def object_matrix(state: SceneState, centre: np.ndarray, radius: float) -> np.ndarray:
    """The file's (Blender-axes) coordinates to the world: normalise, then pose, scale and place."""
    normalise = np.eye(4)
    normalise[:3, :3] *= 1.0 / radius
    normalise[:3, 3] = -centre / radius
    rx, ry, rz = (math.radians(a) for a in (state.pitch, state.roll, state.yaw))
    x = np.array([[1, 0, 0], [0, math.cos(rx), -math.sin(rx)], [0, math.sin(rx), math.cos(rx)]])
    y = np.array([[math.cos(ry), 0, math.sin(ry)], [0, 1, 0], [-math.sin(ry), 0, math.cos(ry)]])
    z = np.array([[math.cos(rz), -math.sin(rz), 0], [math.sin(rz), math.cos(rz), 0], [0, 0, 1]])
    pose = np.eye(4)
    pose[:3, :3] = z @ y @ x * state.scale
    pose[:3, 3] = state.object_location()
    return pose @ normalise


def camera(state: SceneState, size: int, crop: int | None, filter_radius: float) -> dict[str, Any]:
    """The sensor: Blender's camera for ``state`` over a ``size``² frame, of which the centre
    ``crop``² is rendered (None: all of it), through a tent pixel filter of ``filter_radius`` pixels."""
    position, right, up, forward = state.camera_basis()
    fov = math.degrees(2.0 * math.atan(SENSOR_WIDTH_MM / (2.0 * state.focal_length)))
    distance = state.camera_distance()
    film: dict[str, Any] = {"type": "hdrfilm", "width": size, "height": size, "pixel_format": "rgba",
                            "rfilter": {"type": "tent", "radius": filter_radius}}
    if crop is not None and crop < size:
        left = (size - crop) // 2  # as Cycles' border: from the top left
        film.update(crop_offset_x=left, crop_offset_y=left, crop_width=crop, crop_height=crop)
    sensor: dict[str, Any] = {
        "type": "perspective", "fov": fov, "fov_axis": "x",
        "near_clip": max(distance * 1e-4, 1e-6), "far_clip": distance + 1e3 * max(state.scale, 1.0),
        "to_world": look_at(position, forward, up), "film": film,
    }
    if state.fstop > 0:  # Blender: aperture radius = lens / (2 · f-stop), in metres
        sensor.update(type="thinlens", aperture_radius=state.focal_length * 1e-3 / (2.0 * state.fstop),
                      focus_distance=float(np.linalg.norm(state.object_location() - position)))
    return sensor


def look_at(position: np.ndarray, forward: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Mitsuba's camera-to-world (its camera looks down +Z with +X to the image's left)."""
    f = forward / np.linalg.norm(forward)
    left = np.cross(up, f)
    left /= np.linalg.norm(left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, np.cross(f, left), f, position
    return m


def along(z: np.ndarray) -> np.ndarray:
    """A rotation (4×4) taking +Z to the unit vector ``z``: a directional light's to_world."""
    z = np.asarray(z, dtype=np.float64) / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = x, np.cross(z, x), z
    return m


def lights(lights_: list, state: SceneState) -> dict[str, dict[str, Any]]:
    """Each light as a Mitsuba emitter (an area light as an emitting shape)."""
    out: dict[str, dict[str, Any]] = {}
    for i, light in enumerate(lights_):
        name = f"light_{i:03d}"
        if isinstance(light, PointLight):
            out[name] = {"type": "point", "position": light.position().tolist(),
                         "intensity": _rgb(np.asarray(light.rgb) * light.watts / (4.0 * math.pi))}
        elif isinstance(light, SunLight):
            d = direction(state, light.azimuth, light.elevation, light.relative_to)
            out[name] = {"type": "directional", "to_world": along(-d),  # a parameter, where "direction" is not
                         "irradiance": _rgb(np.asarray(light.rgb) * light.strength)}
        elif isinstance(light, AreaLight):
            out[name] = area_light(light, state)
    return out


def area_light(light: AreaLight, state: SceneState) -> dict[str, Any]:
    """A one-sided rectangle or disk at the light's place, its normal toward the object."""
    d = direction(state, light.azimuth, light.elevation, light.relative_to)
    rotation = facing(d) @ np.diag([1.0, -1.0, -1.0])  # Mitsuba emits along +Z, Blender's lights along -Z
    half = light.size / 2.0
    area = light.size**2 if light.shape == "square" else math.pi * half**2
    m = np.eye(4)
    m[:3, :3] = rotation @ np.diag([half, half, 1.0])
    m[:3, 3] = state.object_location() + light.distance * d
    return {"type": "rectangle" if light.shape == "square" else "disk", "to_world": m,
            "emitter": {"type": "area", "radiance": _rgb(np.asarray(light.rgb) * light.watts / (math.pi * area))},
            "bsdf": {"type": "diffuse", "reflectance": _rgb((0.0, 0.0, 0.0))}}


def occluder(state: SceneState) -> dict[str, Any] | None:
    """The grey plate of :class:`~sweep3d.stages.render.cycles.props.Props`, placed the same way."""
    occ = state.occluder
    if occ is None:
        return None
    position, right, up, forward = state.camera_basis()
    centre = state.object_location()
    depth = float(np.dot(centre - position, forward))
    k = OCCLUDER_DEPTH
    radius = state.scale * k
    theta = math.radians(occ.direction)
    towards = math.cos(theta) * right + math.sin(theta) * up
    half = 1.5 * radius
    inner_edge = radius * (1.0 - 2.0 * occ.coverage)
    axis_point = position + forward * depth * k + (centre - position - forward * depth) * k
    m = np.eye(4)
    m[:3, :3] = np.stack([right, up, -forward], axis=1) @ np.diag([half, half, 1.0])
    m[:3, 3] = axis_point + towards * (inner_edge + half)
    return {"type": "rectangle", "to_world": m,
            "bsdf": {"type": "twosided", "bsdf": principled({"base_color": (occ.grey,) * 3})}}


def principled(values: dict[str, Any], texture: Any = None) -> dict[str, Any]:
    """Mitsuba's principled BSDF for Blender Principled BSDF values (``base_color`` linear RGB,
    ``roughness``, ``metallic``, ``specular`` = Specular IOR Level, ``ior``, ``transmission``,
    ``coat``, ``opacity``), with ``texture`` (a loaded bitmap) as the base colour when given.

    Blender's dielectric reflectance at normal incidence is ((ior − 1)/(ior + 1))² · 2 · level;
    Mitsuba's ``specular`` s gives 0.08 · s, so s = that / 0.08. Opacity wraps it in a ``mask``."""
    ior = max(float(values.get("ior", 1.5)), 1.0)  # Blender's IOR input stops at 1 (an MTL's "Ni 0" is common)
    level = float(values.get("specular", 0.5))
    f0 = ((ior - 1.0) / (ior + 1.0)) ** 2 * 2.0 * level
    bsdf: dict[str, Any] = {
        "type": "principled",
        # an MTL's Kd may overshoot 1 by rounding (sweep3d.assets.mtl_values.COLOUR_SLACK; more is refused at
        # load), which Mitsuba refuses as an invalid reflectance: bounded here
        "base_color": texture if texture is not None else _rgb(values.get("base_color", (0.8, 0.8, 0.8)), unit=True),
        "roughness": float(min(max(values.get("roughness", 0.5), 0.0), 1.0)),
        "metallic": float(values.get("metallic", 0.0)),
        "specular": min(max(f0 / 0.08, MIN_SPECULAR), 12.0),  # Mitsuba's eta is infinite at 12.5
    }
    if values.get("coat"):
        bsdf["clearcoat"] = float(values["coat"])
    transmission = float(values.get("transmission", 0.0))
    if transmission > 0:
        bsdf["spec_trans"] = transmission
        del bsdf["specular"]
        bsdf["eta"] = max(ior, 1.0 + MIN_SPECULAR)
    else:
        bsdf = {"type": "twosided", "bsdf": bsdf}  # Blender shades both sides of a face
    opacity = float(values.get("opacity", 1.0))
    if opacity < 1.0:
        bsdf = {"type": "mask", "opacity": opacity, "bsdf": bsdf}
    return bsdf


def _rgb(value: Any, unit: bool = False) -> dict[str, Any]:
    """Mitsuba's RGB of ``value``; with ``unit``, each channel bounded to [0, 1] (a reflectance)."""
    return {"type": "rgb", "value": [min(max(float(c), 0.0), 1.0) if unit else float(c) for c in value]}
