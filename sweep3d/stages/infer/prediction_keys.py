"""The infer stage's cache key: an image, the model that sees it, what counts as correct, and,
where it could be another, the backend that computes (a key means one set of bytes)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Sequence

from sweep3d.cache import Hole, Template, digest, digests
from sweep3d.core import code_identity, is_user_plugin

if TYPE_CHECKING:
    from sweep3d.spec import LoadedSpec, ModelSpec

#: Bumped when inference or evaluation changes results for the same inputs.
INFER_STAGE_VERSION = 2  # 2: correct_top5 and label_ids in every classification row

#: The backend name of ONNX Runtime standing in for torch (see ``onnx_backend``).
STAND_IN = "onnx-as-torch"


def stands_in(spec: LoadedSpec, model: ModelSpec) -> bool:
    """Whether ONNX Runtime stands in for torch for ``model`` when the spec names no backend: a
    built-in model with the built-in evaluator."""
    from sweep3d.stages.infer.models import builtin_model

    return builtin_model(model.name) is not None and spec.evaluator.kind == "classification"


def choose_backend(spec: LoadedSpec, model: ModelSpec) -> str:
    """What computes ``model``'s predictions: "torch", "onnx" (ONNX Runtime's own answers) or
    :data:`STAND_IN` (ONNX Runtime giving torch's ranks: near ties go through torch).

    A backend written in the spec is used as written. Left out, a built-in model with the
    built-in evaluator gets ONNX Runtime standing in for torch, the fastest on CPU
    (benchmarks/RESULTS.md), wherever the renders are made (``--executor ray`` too); a user's
    model gets torch.
    """
    if "backend" in model.model_fields_set:
        return model.backend
    return STAND_IN if stands_in(spec, model) else "torch"


def key_backend(spec: LoadedSpec, model: ModelSpec) -> str | None:
    """The backend ``model``'s prediction keys name: the one that computes them, except each
    model's default (ONNX Runtime standing in for a built-in model, torch for a user's), whose keys
    have always named none. Torch computing for a model ONNX Runtime stands in for is named: the
    two give the same ranks but probabilities apart in the last digits, and one key must mean one
    set of bytes, so neither backend's rows are served to the other."""
    backend = choose_backend(spec, model)
    if backend == STAND_IN or (backend == "torch" and not stands_in(spec, model)):
        return None
    return backend


def infer_base(model_digest: str, evaluator: dict[str, Any], backend: str | None) -> dict[str, Any]:
    """What every prediction key of a run shares: the model, the evaluator and, when named
    (:func:`key_backend`), the backend."""
    base = {"stage": "infer", "v": INFER_STAGE_VERSION, "model": model_digest, "evaluator": evaluator}
    if backend is not None:
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
