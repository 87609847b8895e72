"""Postprocess: 2D controls applied to rendered images (changing them re-renders nothing)."""

from __future__ import annotations

__all__ = [
    "ImageHandoff", "Made", "POST_CONTROLS", "PostControl", "PostprocessStage", "RenderFrame",
    "apply_post", "image_template", "make_image", "post_controls", "truth_digests"
]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.stages.postprocess.apply import apply_post
    from sweep3d.stages.postprocess.controls.post_control import POST_CONTROLS, PostControl
    from sweep3d.stages.postprocess.frame import RenderFrame
    from sweep3d.stages.postprocess.handoff import ImageHandoff
    from sweep3d.stages.postprocess.image_keys import image_template
    from sweep3d.stages.postprocess.post_stage import (
        Made,
        PostprocessStage,
        make_image,
        post_controls,
        truth_digests,
    )

__getattr__, __dir__ = _exports(__name__, {
    "ImageHandoff": ("sweep3d.stages.postprocess.handoff", "ImageHandoff"),
    "Made": ("sweep3d.stages.postprocess.post_stage", "Made"),
    "POST_CONTROLS": ("sweep3d.stages.postprocess.controls.post_control", "POST_CONTROLS"),
    "PostControl": ("sweep3d.stages.postprocess.controls.post_control", "PostControl"),
    "PostprocessStage": ("sweep3d.stages.postprocess.post_stage", "PostprocessStage"),
    "RenderFrame": ("sweep3d.stages.postprocess.frame", "RenderFrame"),
    "apply_post": ("sweep3d.stages.postprocess.apply", "apply_post"),
    "image_template": ("sweep3d.stages.postprocess.image_keys", "image_template"),
    "make_image": ("sweep3d.stages.postprocess.post_stage", "make_image"),
    "post_controls": ("sweep3d.stages.postprocess.post_stage", "post_controls"),
    "truth_digests": ("sweep3d.stages.postprocess.post_stage", "truth_digests"),
})
