"""The postprocess stage's cache key: a render plus the post controls that change it."""

from __future__ import annotations

from typing import Any

from sweep3d.cache import Hole, Template, digest

#: Bumped when post-processing changes pixels for the same inputs.
POST_STAGE_VERSION = 1


def image_key(render: str, controls: list[dict[str, Any]], seed: int | None) -> str:
    """The key of a post-processed image; the render's own key when no post control changes it.

    Args:
        controls: key parts of the effective post controls, in application order.
        seed: the experiment's seed when one of them draws random numbers, else None.
    """
    if not controls:
        return render
    return digest(_image_value(render, controls, seed))


def image_template(controls: list[Any], seed: int | None) -> Template:
    """:func:`image_key`'s value (when ``controls`` is not empty) with holes: ``render`` and any
    in ``controls``, to hash many jobs' keys at once."""
    return Template(_image_value(Hole("render"), controls, seed))


def _image_value(render: str | Hole, controls: list[Any], seed: int | None) -> dict[str, Any]:
    return {"stage": "post", "v": POST_STAGE_VERSION, "render": render, "controls": controls, "seed": seed}
