"""What the object looks like: its material (texture swap) and what hides it (occlusion)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from sweep3d.cache import file_digest
from sweep3d.core import ControlParams, SpecPath, UserError
from sweep3d.stages.render.controls.rendered_control import RENDERED_CONTROLS, RenderedControl
from sweep3d.stages.render.state import Occluder, SceneState

SKINS = ("original", "zebra", "tiger", "cow", "giraffe", "leopard", "image")


@RENDERED_CONTROLS.register("material")
class Material(RenderedControl):
    """Swaps the object's material for a procedural animal skin (``zebra``, ``tiger``, ``cow``,
    ``giraffe``, ``leopard``: shader nodes on object coordinates, so no UVs are needed) or an
    ``image`` texture (``image`` = a path; projected in box mapping), for cue-conflict studies.
    ``scale`` sets the pattern size (1 = a few stripes/spots across the object).

    It also edits the surface per job, on every material of the rendered parts or on the one
    named ``target`` (as the file names it): ``base_color`` ("#rrggbb", sRGB), ``roughness``,
    ``metallic``, ``transmission``, ``opacity`` (0..1 each) and ``emission`` (strength); a value
    left out keeps the material's own. Edits go on copies, so the next job sees the file's
    materials again."""

    order = 40
    frame_fields = {}
    version = 2  # 2: patterns scale with the object's size

    class Params(ControlParams):
        skin: Literal[SKINS] = "original"  # type: ignore[valid-type]
        scale: float = Field(1.0, gt=0.0, le=1000.0)
        image: SpecPath = ""  # relative to the spec file
        target: str = ""  # the material the surface values below edit ("" = all)
        base_color: str = Field("", pattern=r"^(#[0-9a-fA-F]{6})?$")
        roughness: float | None = Field(None, ge=0.0, le=1.0)
        metallic: float | None = Field(None, ge=0.0, le=1.0)
        transmission: float | None = Field(None, ge=0.0, le=1.0)
        opacity: float | None = Field(None, ge=0.0, le=1.0)
        emission: float | None = Field(None, ge=0.0, le=1000.0)

    def params(self, values: dict[str, Any]) -> Params:
        params = self.Params(**values)
        if params.skin == "image" and not params.image:
            raise UserError("material skin 'image' needs image = 'path/to/texture.png'")
        return params

    def is_identity(self, values: dict[str, Any]) -> bool:
        return values.get("skin", "original") == "original" and not _surface(values)

    def canonical(self, values: dict[str, Any]) -> dict[str, Any]:
        """As before surface edits existed when there are none (a skin's renders keep their keys)."""
        out = {k: v for k, v in super().canonical(values).items() if k not in SURFACE and k != "target"}
        if out.get("skin") == "image" and out.get("image"):
            out["image"] = file_digest(out["image"])  # the texture's content, not its path
        else:
            out.pop("image", None)
        surface = _surface(values)
        if surface:
            out["surface"] = {"target": values.get("target", ""), **surface}
        return out

    def apply(self, state: SceneState, params: Params) -> None:
        state.skin, state.skin_scale = params.skin, params.scale
        state.skin_image = params.image or None
        surface = _surface(params.model_dump())
        if surface:
            if "base_color" in surface:
                surface["base_color"] = srgb_to_linear(surface["base_color"])
            state.material_edits += ((params.target, tuple(sorted(surface.items()))),)


#: The surface values the material control edits (Principled BSDF inputs, see ``material_edits``).
SURFACE = ("base_color", "roughness", "metallic", "transmission", "opacity", "emission")


def _surface(values: dict[str, Any]) -> dict[str, Any]:
    """The surface values given (not left at "keep the material's own"), colours in lower case."""
    out = {k: values[k] for k in SURFACE if values.get(k) not in (None, "")}
    if "base_color" in out:
        out["base_color"] = str(out["base_color"]).lower()
    return out


def srgb_to_linear(color: str) -> tuple[float, float, float]:
    """A "#rrggbb" sRGB colour as the linear RGB a Principled BSDF takes."""
    h = color.lstrip("#")
    channels = (int(h[i : i + 2], 16) / 255.0 for i in (0, 2, 4))
    return tuple(c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in channels)  # type: ignore[return-value]


@RENDERED_CONTROLS.register("occlusion")
class Occlusion(RenderedControl):
    """A flat grey plate between camera and object hiding ``coverage`` (0..1) of the object's
    width, coming in from ``direction`` (degrees in the image: 0 = right, 90 = top)."""

    order = 40
    frame_fields = {}
    periodic = {"direction": 360.0}

    class Params(ControlParams):
        coverage: float = Field(0.0, ge=0.0, le=1.0)
        direction: float = 0.0
        grey: float = Field(0.5, ge=0.0, le=1.0)

    def is_identity(self, values: dict[str, Any]) -> bool:
        return float(values.get("coverage", 0.0)) == 0.0

    def apply(self, state: SceneState, params: Params) -> None:
        if params.coverage > 0:
            state.occluder = Occluder(params.coverage, params.direction, params.grey)
