"""Postprocess: 2D controls applied to rendered images (changing them re-renders nothing)."""

from sweep3d.stages.postprocess.controls import PostControl
from sweep3d.stages.postprocess.stage import apply_post, postprocess_stage

__all__ = ["PostControl", "apply_post", "postprocess_stage"]
