"""Postprocess: 2D controls applied to rendered images (changing them re-renders nothing)."""

from sweep3d.stages.postprocess.controls import POST_CONTROLS, PostControl
from sweep3d.stages.postprocess.stage import PostprocessStage, apply_post

__all__ = ["POST_CONTROLS", "PostControl", "PostprocessStage", "apply_post"]
