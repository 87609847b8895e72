"""Built-in rendered controls: they edit a :class:`~sweep3d.stages.render.state.SceneState`."""

from sweep3d.stages.render.controls.appearance import SKINS, Material, Occlusion
from sweep3d.stages.render.controls.geometry import Camera, Orientation, PinToGround, Position, Scale
from sweep3d.stages.render.controls.lighting import Background, Denoiser, Hdri, PointLightControl, SkyControl
from sweep3d.stages.render.controls.rendered_control import RENDERED_CONTROLS, RenderedControl
from sweep3d.stages.render.controls.studio_lights import AreaLightControl, SunLightControl

__all__ = ["RENDERED_CONTROLS", "SKINS", "AreaLightControl", "Background", "Camera", "Denoiser", "Hdri", "Material",
           "Occlusion", "Orientation", "PinToGround", "PointLightControl", "Position", "RenderedControl", "Scale",
           "SkyControl", "SunLightControl"]
