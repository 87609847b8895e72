"""A worker's Mitsuba scene kept between jobs: loaded once per structure, then changed in place.

Why: describing a job afresh to ``load_dict`` costs tens of milliseconds, and under the
``llvm_ad_rgb`` variant a freshly loaded scene bakes its values into new kernels, compiled again
(about a second) whenever a yaw, a camera or a light changes. A job that changes only values
(the object's pose, the camera, lights' places and strengths, the world's rotation and strength,
material values, the occluder's place) is rendered by the kept scene with those parameters
updated (``mitsuba.traverse``), so its kernels are reused. Under a JIT variant each value is set
opaque (an array in memory, not a constant compiled into the kernel), so one recording of the
frozen render (``frozen.py``) serves every job of the structure.

The object's pose: under ``llvm_ad_rgb`` the pieces sit untransformed in a shape group and the
pose is its instance's ``to_world``, a value like any other (a new pose rebuilds only Embree's
top level); under ``scalar_rgb`` (whose path tracer crashes on an instance with
``hide_emitters``) each piece's ``to_world`` is applied to its vertices here (``poses``).

Determinism: a freshly loaded scene takes every value through the parameter update, a kept one
the values that changed since (the vertices of an unmoved piece stay as they are), so a
render's pixels depend on the job alone, never on the job the worker rendered before it
(tests/stages/render/test_mitsuba_kept.py renders a sequence both ways).

A value with no parameter to update (a description key Mitsuba does not expose) is part of the
structure: changing it loads the scene afresh.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: Description keys whose children Mitsuba's parameters name otherwise (``mask``'s and
#: ``twosided``'s nested BSDF).
NESTED = {("mask", "bsdf"): "nested_bsdf", ("twosided", "bsdf"): "brdf_0"}
#: Description keys that Mitsuba's parameters name otherwise.
RENAMED = {("perspective", "fov"): "x_fov", ("thinlens", "fov"): "x_fov"}


@dataclass
class Split:
    """A description split into what needs a new load and what a parameter update can change."""

    structure: list[tuple[str, Any]] = field(default_factory=list)  # (path, value): types, sizes, names, bitmaps
    values: dict[str, Any] = field(default_factory=dict)  # parameter name → float, RGB list or 4×4 array
    poses: dict[str, np.ndarray] = field(default_factory=dict)  # object shape name → its to_world


def split(description: dict[str, Any]) -> Split:
    """Walk a scene description (numpy 4×4 matrices, not yet converted): floats and matrices are
    values under the name Mitsuba's parameters give them; the objects' (``object_*``) poses apart;
    everything else (types, file names, integers, flags, loaded bitmaps) is structure."""
    out = Split()

    def walk(node: dict[str, Any], path: str, param: str) -> None:
        kind = node.get("type")
        for key, value in node.items():
            here = f"{path}.{key}" if path else key
            name = NESTED.get((kind, key)) or RENAMED.get((kind, key)) or key
            there = f"{param}.{name}" if param else name
            if isinstance(value, dict):
                walk(value, here, there)
            elif isinstance(value, np.ndarray) and path.startswith("object_") and key == "to_world" and "." not in path:
                out.poses[path] = value
            elif _is_value(value):
                out.values[there] = value
            else:
                out.structure.append((here, id(value) if _is_loaded(value) else _frozen(value)))

    walk(description, "", "")
    return out


def _is_value(value: Any) -> bool:
    if isinstance(value, bool):
        return False
    if isinstance(value, float):
        return True
    if isinstance(value, np.ndarray):
        return value.dtype.kind == "f"
    return isinstance(value, list) and bool(value) and all(isinstance(v, float) for v in value)


def _is_loaded(value: Any) -> bool:
    """A Mitsuba object (a loaded bitmap or texture), kept by the worker: the same object, the same structure."""
    return not isinstance(value, (str, int, float, list, tuple, type(None), np.ndarray))


def _frozen(value: Any) -> Any:
    if isinstance(value, list):
        return tuple(_frozen(v) for v in value)
    if isinstance(value, np.ndarray):
        return tuple(value.ravel().tolist())
    return value


def without_poses(description: dict[str, Any], poses: dict[str, np.ndarray]) -> dict[str, Any]:
    """The description with its objects untransformed (their poses are applied to the vertices)."""
    return {k: ({kk: vv for kk, vv in v.items() if kk != "to_world"} if k in poses else v)
            for k, v in description.items()}


def _no_op(_value: Any) -> None:
    """``scalar_rgb`` has no kernels for a value to be baked into."""


def _jit_opaque() -> Any:
    import drjit as dr

    return dr.make_opaque


class KeptScene:
    """The latest structure's loaded scene, its parameters and its objects' untransformed vertices.

    Args:
        mi: the ``mitsuba`` module with its variant set.
        converted: turns a description's numpy matrices into Mitsuba transforms (``MitsubaScene.converted``).
    """

    def __init__(self, mi: Any, converted: Any) -> None:
        self.mi = mi
        self.converted = converted
        # under a JIT variant, a value is set as an array in memory, not a constant in the kernel:
        # one recording of a frozen render (frozen.py) and one compilation serve every value
        self.opaque = _no_op if mi.variant().startswith("scalar") else _jit_opaque()
        self.key: tuple | None = None
        self.scene: Any = None
        self.params: Any = None
        self.base: dict[str, tuple[np.ndarray, np.ndarray | None]] = {}  # shape → (positions, normals)
        self.loads = 0  # fresh loads so far (the rest were updates)
        self.applied: dict[str, Any] = {}  # parameter or shape → the value or pose it last took

    def scene_for(self, description: dict[str, Any]) -> Any:
        """The description's scene: the kept one updated when only values changed, else loaded afresh."""
        parts = split(description)
        key = self._key(parts)
        if key != self.key:
            self._load(description, parts)
            key = self._key(parts)
        self.key = key
        self._update(parts)
        return self.scene

    def _key(self, parts: Split) -> tuple:
        """What must match the kept scene's for an update to do: the structure, and the values
        no parameter updates."""
        unmapped = tuple((name, _frozen(value)) for name, value in parts.values.items()
                         if self.params is None or self._parameter(name) is None)
        return tuple(parts.structure), tuple(sorted(parts.poses)), unmapped

    def _parameter(self, name: str) -> str | None:
        """The parameter a description value sets (a texture's constant is its ``.value``), or None."""
        for candidate in (name, f"{name}.value"):
            if candidate in self.params:
                return candidate
        return None

    def clear(self) -> None:
        """Forget the kept scene (the next job loads afresh)."""
        self.key = self.scene = self.params = None
        self.base, self.applied = {}, {}

    def _load(self, description: dict[str, Any], parts: Split) -> None:
        self.scene = self.mi.load_dict(self.converted(without_poses(description, parts.poses)), optimize=False)
        self.params = self.mi.traverse(self.scene)
        self.base, self.applied = {}, {}  # the first update sets every value, as later ones set what changed
        for shape in parts.poses:
            positions = np.array(self.params[f"{shape}.vertex_positions"], dtype=np.float32)
            normals_key = f"{shape}.vertex_normals"
            normals = np.array(self.params[normals_key], dtype=np.float32) if normals_key in self.params else None
            self.base[shape] = (positions, normals if normals is not None and normals.size else None)
        self.loads += 1

    def _update(self, parts: Split) -> None:
        """Set the values and poses that differ from those the kept scene last took (all of them
        after a load), then let Mitsuba recompute what depends on them."""
        params, applied = self.params, self.applied
        for name, value in parts.values.items():
            target = self._parameter(name)
            frozen = _frozen(value)
            if target is None or applied.get(target) == frozen:
                continue  # part of the key (the scene was loaded with it), or as the last job left it
            kind = type(params[target])
            if isinstance(value, np.ndarray):
                params[target] = kind(value.tolist())
            elif isinstance(value, list):
                params[target] = kind(*value) if len(value) > 1 else kind(value[0])
            else:
                params[target] = kind(value)
            self.opaque(params[target])
            applied[target] = frozen
        turned_by: dict[bytes, np.ndarray] = {}  # the objects' pieces share one pose: its inverse once
        for shape, matrix in parts.poses.items():
            pose = matrix.tobytes()
            if applied.get(shape) == pose:
                continue  # not moved: its vertices and bounding volumes stand
            positions, normals = self.base[shape]
            linear = matrix[:3, :3]
            moved = positions.reshape(-1, 3).astype(np.float64) @ linear.T + matrix[:3, 3]
            key = f"{shape}.vertex_positions"
            params[key] = type(params[key])(moved.astype(np.float32).ravel())  # the variant's float array
            if normals is not None:
                inverse = turned_by.setdefault(pose, np.linalg.inv(linear))
                turned = normals.reshape(-1, 3).astype(np.float64) @ inverse
                turned /= np.maximum(np.linalg.norm(turned, axis=1, keepdims=True), 1e-30)
                key = f"{shape}.vertex_normals"
                params[key] = type(params[key])(turned.astype(np.float32).ravel())
            applied[shape] = pose
        params.update()
