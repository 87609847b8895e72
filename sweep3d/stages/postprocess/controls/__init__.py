"""Built-in post-processing controls: pure functions from one image to another."""

from sweep3d.stages.postprocess.controls.base import PostControl
from sweep3d.stages.postprocess.controls.photometric import Blur, BrightnessContrast, Noise

__all__ = ["Blur", "BrightnessContrast", "Noise", "PostControl"]
