"""The infer stage's cache key: an image, the model that sees it, and what counts as correct."""

from __future__ import annotations

from typing import Any, Sequence

from sweep3d.cache import Hole, Template, digest, digests
from sweep3d.core import code_identity, is_user_plugin

#: Bumped when inference or evaluation changes results for the same inputs.
INFER_STAGE_VERSION = 2  # 2: correct_top5 and label_ids in every classification row


def infer_base(model_digest: str, evaluator: dict[str, Any], backend: str) -> dict[str, Any]:
    """What every prediction key of a run shares: the model, the evaluator and the backend."""
    base = {"stage": "infer", "v": INFER_STAGE_VERSION, "model": model_digest, "evaluator": evaluator}
    if backend != "torch":  # another backend may differ in the last bits: its own answers
        base["backend"] = backend
    return base


def evaluator_key(settings: Any) -> dict[str, Any]:
    """The evaluator's part of prediction keys: its kind and the settings that change its rows,
    and, when it reads truth passes, their version (a new mask recipe re-evaluates)."""
    from sweep3d.core import TRUTH_VERSION
    from sweep3d.stages.infer.evaluators import EVALUATORS

    evaluator = EVALUATORS.get(settings.kind)
    part = {"kind": settings.kind, **evaluator.from_settings(settings).key_part()}
    if evaluator.passes:
        part["truth"] = TRUTH_VERSION
    if is_user_plugin(settings.kind):  # editing a user's evaluator re-evaluates
        part["code"] = code_identity(evaluator)
    return part


def pred_key(base: dict[str, Any], image: str, truth: list[Any]) -> str:
    """A job's prediction key: ``base`` plus its image and its ground truth."""
    return digest(_pred_value(base, image, truth))


def pred_keys(base: dict[str, Any], images: Sequence[str], truth: list[Any]) -> list[str]:
    """:func:`pred_key` of many jobs that share ``base`` and ``truth`` (one object's jobs)."""
    return digests(Template(_pred_value(base, Hole("image"), truth)).fill(["image"], image=images))


def _pred_value(base: dict[str, Any], image: str | Hole, truth: list[Any]) -> dict[str, Any]:
    return {**base, "image": image, "truth": truth}
