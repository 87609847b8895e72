"""What the object looks like: its material (texture swap) and what hides it (occlusion)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from sweep3d.cache.keys import file_digest
from sweep3d.controls import ControlParams, SpecPath
from sweep3d.errors import UserError
from sweep3d.stages.render.controls.base import RENDERED_CONTROLS, RenderedControl
from sweep3d.stages.render.state import Occluder, SceneState

SKINS = ("original", "zebra", "tiger", "cow", "giraffe", "leopard", "image")


@RENDERED_CONTROLS.register("material")
class Material(RenderedControl):
    """Swaps the object's material for a procedural animal skin (``zebra``, ``tiger``, ``cow``,
    ``giraffe``, ``leopard``: shader nodes on object coordinates, so no UVs are needed) or an
    ``image`` texture (``image`` = a path; projected in box mapping), for cue-conflict studies.
    ``scale`` sets the pattern size (1 = a few stripes/spots across the object)."""

    order = 40
    frame_fields = {}
    version = 2  # 2: patterns scale with the object's size

    class Params(ControlParams):
        skin: Literal[SKINS] = "original"  # type: ignore[valid-type]
        scale: float = Field(1.0, gt=0.0, le=1000.0)
        image: SpecPath = ""  # relative to the spec file

    def params(self, values: dict[str, Any]) -> Params:
        params = self.Params(**values)
        if params.skin == "image" and not params.image:
            raise UserError("material skin 'image' needs image = 'path/to/texture.png'")
        return params

    def is_identity(self, values: dict[str, Any]) -> bool:
        return values.get("skin", "original") == "original"

    def canonical(self, values: dict[str, Any]) -> dict[str, Any]:
        out = dict(super().canonical(values))
        if out.get("skin") == "image" and out.get("image"):
            out["image"] = file_digest(out["image"])  # the texture's content, not its path
        else:
            out.pop("image", None)
        return out

    def apply(self, state: SceneState, params: Params) -> None:
        state.skin, state.skin_scale = params.skin, params.scale
        state.skin_image = params.image or None


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
