"""Postprocess: 2D controls applied to rendered images (changing them re-renders nothing)."""

from __future__ import annotations

__all__ = ["POST_CONTROLS", "ImageHandoff", "Made", "PostControl", "PostprocessStage", "apply_post", "make_image",
           "post_controls", "truth_digests"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.lazy import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
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

__getattr__, __dir__ = _exports(__name__, {
    'ImageHandoff': ('sweep3d.stages.postprocess.handoff', 'ImageHandoff'),
    'Made': ('sweep3d.stages.postprocess.stage', 'Made'),
    'POST_CONTROLS': ('sweep3d.stages.postprocess.controls', 'POST_CONTROLS'),
    'PostControl': ('sweep3d.stages.postprocess.controls', 'PostControl'),
    'PostprocessStage': ('sweep3d.stages.postprocess.stage', 'PostprocessStage'),
    'apply_post': ('sweep3d.stages.postprocess.stage', 'apply_post'),
    'make_image': ('sweep3d.stages.postprocess.stage', 'make_image'),
    'post_controls': ('sweep3d.stages.postprocess.stage', 'post_controls'),
    'truth_digests': ('sweep3d.stages.postprocess.stage', 'truth_digests'),
})
