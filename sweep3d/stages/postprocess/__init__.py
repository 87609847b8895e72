"""Postprocess: 2D controls applied to rendered images (changing them re-renders nothing)."""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used.
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

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
