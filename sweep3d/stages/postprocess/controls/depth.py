"""Depth-aware corruptions: fog and a lens's defocus, from the depth pass of the job's own render.

They declare ``passes = ("depth",)``: the render stage then writes the depth pass (see
``sweep3d.driver.passes``) and the postprocess stage hands it to ``apply`` with the camera, as a
:class:`~sweep3d.stages.postprocess.frame.RenderFrame`. Distances are in object radii (Blender
metres: the object fits a sphere of radius 1). The optics are in ``postprocess.depth_effects``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import Field

from sweep3d.core import ControlParams
from sweep3d.stages.postprocess.controls.post_control import POST_CONTROLS, PostControl
from sweep3d.stages.postprocess.depth_effects import defocus, fog, signed_coc
from sweep3d.stages.postprocess.frame import RenderFrame

HEX = r"^#[0-9a-fA-F]{6}$"


def _depth(frame: RenderFrame | None, control: str) -> RenderFrame:
    if frame is None or frame.depth is None:
        raise ValueError(f"the {control} control needs the render's depth pass: apply it through the postprocess "
                         "stage (or pass a RenderFrame with a depth)")
    return frame


@POST_CONTROLS.register("fog")
class Fog(PostControl):
    """Homogeneous fog: a surface at ray distance d keeps exp(-``density`` · d) of its light and the
    rest turns to the airlight ``color`` ("#rrggbb", sRGB: what a fully fogged pixel shows).

    ``density`` is the extinction coefficient per object radius (0 = no fog, the neutral value;
    0.3 leaves a third of the object's centre at the default framing, 3.7 radii away). Where no
    surface was hit, the background is ``background_distance`` away along the ray; 0 (the default)
    puts it at infinity, fully fogged, as a homogeneous medium hides an environment at infinity.
    """

    passes = ("depth",)

    class Params(ControlParams):
        density: float = Field(0.0, ge=0.0, le=1e4)
        color: str = Field("#cccccc", pattern=HEX)
        background_distance: float = Field(0.0, ge=0.0, le=1e6)

    def canonical(self, values: dict[str, Any]) -> dict[str, Any]:
        out = super().canonical(values)
        if "color" in out:
            out["color"] = str(out["color"]).lower()
        return out

    def is_identity(self, values: dict[str, Any]) -> bool:
        return float(values.get("density", 0.0)) == 0.0

    def apply(self, image: np.ndarray, params: Params, rng: np.random.Generator,
              frame: RenderFrame | None = None) -> np.ndarray:
        if params.density == 0:
            return image
        distance = _depth(frame, "fog").ray_distance()
        if params.background_distance > 0:
            distance = np.where(np.isinf(distance), params.background_distance, distance)
        return fog(image, distance, params.density, airlight(params.color))


def airlight(color: str) -> np.ndarray:
    """A "#rrggbb" sRGB colour as linear RGB (3,)."""
    from sweep3d.core import srgb_to_linear

    h = color.lstrip("#")
    return srgb_to_linear(np.array([int(h[i : i + 2], 16) / 255.0 for i in (0, 2, 4)])).astype(np.float64)


@POST_CONTROLS.register("defocus")
class Defocus(PostControl):
    """A thin lens's depth of field on the pinhole render: the rendered camera's focal length at
    f-number ``fstop`` (0 = pinhole, no blur: the neutral value), focused at ``focus_distance``
    object radii along the camera's axis (0 = at the object's centre, as the ``camera`` control's
    ``fstop`` focuses). The aperture's radius is focal length / (2 · fstop), as in Blender.
    """

    passes = ("depth",)

    class Params(ControlParams):
        fstop: float = Field(0.0, ge=0.0, le=1000.0)
        focus_distance: float = Field(0.0, ge=0.0, le=1e6)

    def is_identity(self, values: dict[str, Any]) -> bool:
        return float(values.get("fstop", 0.0)) == 0.0

    def apply(self, image: np.ndarray, params: Params, rng: np.random.Generator,
              frame: RenderFrame | None = None) -> np.ndarray:
        if params.fstop == 0:
            return image
        frame = _depth(frame, "defocus")
        focus = params.focus_distance or frame.subject_distance
        aperture = frame.focal_length * 1e-3 / (2.0 * params.fstop)  # radius, in object radii (metres)
        coc = signed_coc(frame.depth, focus, frame.focal_px, aperture)
        widest = float(np.hypot(*image.shape[:2]))  # a wider blur than the image's diagonal changes nothing more
        return defocus(image, np.clip(coc, -widest, widest))
