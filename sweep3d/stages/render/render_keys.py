"""The render stage's cache keys: what changes a rendered image, and nothing else.

``render_key`` hashes the Blender version, the render settings that change pixels (with the
resolved frame), the mesh's and the HDRI's *content*, the object's look when the spec gives one
(parts, material overrides, smoothing), and the rendered controls that apply to the
job and are not at their neutral values. Extra passes leave the RGB image alone, so they are keyed
apart: ``parts_key`` names what a UV pass saw in one render, ``truth_key`` what the truth passes
(mask, depth) gave it.
"""

from __future__ import annotations

from typing import Any, Sequence

from sweep3d.cache import Hole, Template, digest, digests
from sweep3d.core import EDITED_TRUTH_VERSION, PARTS_LAYOUT, TRUTH_VERSION

#: Bumped when rendering changes pixels for the same inputs, so old renders are not reused.
RENDER_STAGE_VERSION = 1


def scene_key(blender: str, settings: dict[str, Any], object_digest: str, environment: dict[str, Any],
              look: dict[str, Any] | None = None, engine: dict[str, Any] | None = None) -> str:
    """Everything of a render key that is fixed for one (object, environment) scene, hashed once.

    Args:
        look: the object's ``parts``, material overrides and ``auto_smooth``
            (``ObjectSpec.look_key``); None leaves the key as it was before they existed.
        engine: a renderer other than Cycles (``Backend.key``: its name, version and
            variant), which then stands in for Blender's version; None: Cycles, keyed as before.
    """
    value = {"stage": "render", "v": RENDER_STAGE_VERSION, "blender": blender, "settings": settings,
             "passes": [],  # the RGB image's; extra passes leave it alone and are keyed apart
             "object": object_digest, "environment": environment}
    if engine:
        del value["blender"]
        value["engine"] = engine
    if look:
        value["look"] = look
    return digest(value)


def render_key(scene: str, controls: list[dict[str, Any]]) -> str:
    """A job's render key: its scene and the key parts of its effective rendered controls."""
    return digest(_render_value(scene, controls))


def render_template(scene: str, controls: list[Any]) -> Template:
    """:func:`render_key`'s value with holes (in ``controls``), to hash many jobs' keys at once."""
    return Template(_render_value(scene, controls))


def _render_value(scene: str, controls: list[Any]) -> dict[str, Any]:
    return {"scene": scene, "controls": controls}


def parts_key(render: str) -> str:
    """The key of the visible parts a UV pass records for one render."""
    return digest(_parts_value(render))


def parts_keys(renders: Sequence[str]) -> list[str]:
    """:func:`parts_key` of many renders."""
    return digests(Template(_parts_value(Hole("render"))).fill(["render"], render=renders))


def _parts_value(render: str | Hole) -> dict[str, Any]:
    return {"stage": "parts", "layout": PARTS_LAYOUT, "render": render}


def truth_key(render: str, passes: Sequence[str], edited: bool = False) -> str:
    """The key of the ground truth (mask, depth, box, visibility) the truth passes give one render;
    ``edited``: a control of its scene has an ``edit`` (:data:`EDITED_TRUTH_VERSION` applies)."""
    return digest(_truth_value(render, passes, edited))


def truth_keys(renders: Sequence[str], passes: Sequence[str], edited: bool = False) -> list[str]:
    """:func:`truth_key` of many renders."""
    return digests(Template(_truth_value(Hole("render"), passes, edited)).fill(["render"], render=renders))


def _truth_value(render: str | Hole, passes: Sequence[str], edited: bool) -> dict[str, Any]:
    value = {"stage": "truth", "v": TRUTH_VERSION, "passes": sorted(passes), "render": render}
    if edited:  # only there: the other renders' truth rows stay valid
        value["edited"] = EDITED_TRUTH_VERSION
    return value
