"""Built-in rendered controls: they edit a :class:`~sweep3d.stages.render.state.SceneState`."""

from sweep3d.stages.render.controls.base import RenderedControl
from sweep3d.stages.render.controls.geometry import Camera, Orientation, Position, Scale

__all__ = ["Camera", "Orientation", "Position", "RenderedControl", "Scale"]
