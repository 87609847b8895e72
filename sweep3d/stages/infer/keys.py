"""The infer stage's cache key: an image, the model that sees it, and what counts as correct."""

from __future__ import annotations

from typing import Any

from sweep3d.cache.keys import digest

#: Bumped when inference or evaluation changes results for the same inputs.
INFER_STAGE_VERSION = 1


def infer_base(model_digest: str, evaluator: dict[str, Any], backend: str) -> dict[str, Any]:
    """What every prediction key of a run shares: the model, the evaluator and the backend."""
    base = {"stage": "infer", "v": INFER_STAGE_VERSION, "model": model_digest, "evaluator": evaluator}
    if backend != "torch":  # another backend may differ in the last bits: its own answers
        base["backend"] = backend
    return base


def pred_key(base: dict[str, Any], image: str, truth: list[Any]) -> str:
    """A job's prediction key: ``base`` plus its image and its ground truth."""
    return digest({**base, "image": image, "truth": truth})
