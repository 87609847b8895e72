"""Capture and transmission artefacts: JPEG compression and a cutout patch."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image
from pydantic import Field

from sweep3d.core import ControlParams, to_uint8
from sweep3d.stages.postprocess.controls.post_control import POST_CONTROLS, PostControl


@POST_CONTROLS.register("jpeg")
class Jpeg(PostControl):
    """JPEG compression at ``quality`` 1..100 (100 = none, the neutral value)."""

    class Params(ControlParams):
        quality: int = Field(100, ge=1, le=100)

    def apply(self, image: np.ndarray, params: Params, rng: np.random.Generator) -> np.ndarray:
        if params.quality == 100:
            return image
        buf = io.BytesIO()
        Image.fromarray(to_uint8(image), "RGB").save(buf, format="JPEG", quality=params.quality)
        buf.seek(0)
        with Image.open(buf) as decoded:
            return np.asarray(decoded.convert("RGB"), dtype=np.float32) / 255.0


@POST_CONTROLS.register("cutout")
class Cutout(PostControl):
    """A square patch of flat ``value`` (0 black .. 1 white): side ``size`` as a fraction of the
    image side (0 = none), centred at (``x``, ``y``) in -1..1 frame coordinates (+y up)."""

    class Params(ControlParams):
        size: float = Field(0.0, ge=0.0, le=1.0)
        x: float = Field(0.0, ge=-1.0, le=1.0)
        y: float = Field(0.0, ge=-1.0, le=1.0)
        value: float = Field(0.5, ge=0.0, le=1.0)

    def apply(self, image: np.ndarray, params: Params, rng: np.random.Generator) -> np.ndarray:
        if params.size == 0:
            return image
        h, w = image.shape[:2]
        side = max(1, round(params.size * min(h, w)))
        cx, cy = (params.x + 1) / 2 * w, (1 - params.y) / 2 * h
        top, left = int(round(cy - side / 2)), int(round(cx - side / 2))
        out = image.copy()
        out[max(top, 0) : max(top + side, 0), max(left, 0) : max(left + side, 0)] = params.value
        return out
