"""Built-in post-processing controls: pure functions from one image to another."""

from sweep3d.stages.postprocess.controls.artifacts import Cutout, Jpeg
from sweep3d.stages.postprocess.controls.corruptions import CORRUPTIONS, Corruption
from sweep3d.stages.postprocess.controls.depth import Defocus, Fog
from sweep3d.stages.postprocess.controls.photometric import Blur, BrightnessContrast, ColorJitter, Noise
from sweep3d.stages.postprocess.controls.post_control import POST_CONTROLS, PostControl

__all__ = ["CORRUPTIONS", "POST_CONTROLS", "Blur", "BrightnessContrast", "ColorJitter", "Corruption", "Cutout", "Defocus",
           "Fog", "Jpeg", "Noise", "PostControl"]
