"""Blur, noise, brightness/contrast and colour jitter."""

from __future__ import annotations

import numpy as np
from pydantic import Field

from sweep3d.core import ControlParams
from sweep3d.stages.postprocess.controls.post_control import POST_CONTROLS, PostControl


@POST_CONTROLS.register("blur")
class Blur(PostControl):
    """Gaussian blur; ``sigma`` in pixels (0 = none, typical range 0..4)."""

    class Params(ControlParams):
        sigma: float = Field(0.0, ge=0.0, le=1000.0)

    def apply(self, image: np.ndarray, params: Params, rng: np.random.Generator) -> np.ndarray:
        if params.sigma == 0:
            return image
        from scipy import ndimage  # here: render workers and the CLI import this module, not scipy

        return ndimage.gaussian_filter(image, sigma=(params.sigma, params.sigma, 0), mode="nearest")


@POST_CONTROLS.register("noise")
class Noise(PostControl):
    """Additive Gaussian pixel noise; ``std`` in units of the [0, 1] range (0 = none)."""

    stochastic = True

    class Params(ControlParams):
        std: float = Field(0.0, ge=0.0, le=100.0)

    def apply(self, image: np.ndarray, params: Params, rng: np.random.Generator) -> np.ndarray:
        if params.std == 0:
            return image
        noisy = image + rng.normal(0.0, params.std, size=image.shape).astype(np.float32)
        return np.clip(noisy, 0.0, 1.0)


@POST_CONTROLS.register("brightness_contrast")
class BrightnessContrast(PostControl):
    """``brightness`` is added (-1..1) and ``contrast`` scales about mid-grey (1 = unchanged)."""

    class Params(ControlParams):
        brightness: float = Field(0.0, ge=-1.0, le=1.0)
        contrast: float = Field(1.0, ge=0.0, le=100.0)

    def apply(self, image: np.ndarray, params: Params, rng: np.random.Generator) -> np.ndarray:
        if params.brightness == 0 and params.contrast == 1:
            return image
        out = (image - 0.5) * params.contrast + 0.5 + params.brightness
        return np.clip(out, 0.0, 1.0).astype(np.float32)


@POST_CONTROLS.register("color_jitter")
class ColorJitter(PostControl):
    """Shifts ``hue`` (turns, -0.5..0.5) and scales ``saturation`` (1 = unchanged, 0 = grey)."""

    class Params(ControlParams):
        hue: float = Field(0.0, ge=-0.5, le=0.5)
        saturation: float = Field(1.0, ge=0.0, le=10.0)

    def apply(self, image: np.ndarray, params: Params, rng: np.random.Generator) -> np.ndarray:
        if params.hue == 0 and params.saturation == 1:
            return image
        from skimage.color import hsv2rgb, rgb2hsv  # noqa: PLC0415  (scikit-image comes with imagecorruptions)

        hsv = rgb2hsv(np.clip(image, 0.0, 1.0))
        hsv[..., 0] = (hsv[..., 0] + params.hue) % 1.0
        hsv[..., 1] = np.clip(hsv[..., 1] * params.saturation, 0.0, 1.0)
        return hsv2rgb(hsv).astype(np.float32)
