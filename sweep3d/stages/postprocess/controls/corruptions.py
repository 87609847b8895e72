"""The 19 ImageNet-C corruptions (Hendrycks & Dietterich), through ``imagecorruptions-imaug``.

The library draws from numpy's global generator (and two corruptions take a ``seed``), so each
call is seeded from the job's generator: a cached image is reproducible from its key.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import Field

from sweep3d.core import ControlParams, UserError
from sweep3d.stages.postprocess.controls.post_control import POST_CONTROLS, PostControl

CORRUPTIONS = (
    "gaussian_noise", "shot_noise", "impulse_noise", "defocus_blur", "glass_blur", "motion_blur",
    "zoom_blur", "snow", "frost", "fog", "brightness", "contrast", "elastic_transform", "pixelate",
    "jpeg_compression", "speckle_noise", "gaussian_blur", "spatter", "saturate",
)
_TAKES_SEED = {"impulse_noise", "glass_blur"}
MIN_SIDE = 32  # the library refuses smaller images


@POST_CONTROLS.register("corruption")
class Corruption(PostControl):
    """One ImageNet-C corruption: ``name`` (one of the 19) at ``severity`` 1..5 (0 = none)."""

    stochastic = True

    class Params(ControlParams):
        name: Literal[CORRUPTIONS] = "gaussian_noise"  # type: ignore[valid-type]
        severity: int = Field(0, ge=0, le=5)

    def is_identity(self, values: dict[str, Any]) -> bool:
        return int(values.get("severity", 0)) == 0

    def apply(self, image: np.ndarray, params: Params, rng: np.random.Generator) -> np.ndarray:
        if params.severity == 0:
            return image
        from imagecorruptions import corrupt  # noqa: PLC0415  (imports numba; only when used)

        h, w = image.shape[:2]
        if min(h, w) < MIN_SIDE:
            raise UserError(f"ImageNet-C corruptions need images of at least {MIN_SIDE}×{MIN_SIDE} pixels; "
                            f"set render.resolution ≥ {MIN_SIDE}")
        seed = int(rng.integers(0, 2**31 - 1))
        np.random.seed(seed)
        kwargs = {"seed": seed} if params.name in _TAKES_SEED else {}
        pixels = (np.clip(image, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
        out = corrupt(pixels, severity=params.severity, corruption_name=params.name, **kwargs)
        return np.asarray(out, dtype=np.float32)[..., :3] / 255.0
