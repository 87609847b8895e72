"""Postprocess: 2D controls applied to rendered images (changing them re-renders nothing)."""

from sweep3d.stages.postprocess.controls import POST_CONTROLS, PostControl
from sweep3d.stages.postprocess.handoff import ImageHandoff
from sweep3d.stages.postprocess.stage import (
    Made,
    PostprocessStage,
    apply_post,
    make_image,
    post_controls,
    truth_digests,
)

__all__ = ["POST_CONTROLS", "ImageHandoff", "Made", "PostControl", "PostprocessStage", "apply_post", "make_image",
           "post_controls", "truth_digests"]
