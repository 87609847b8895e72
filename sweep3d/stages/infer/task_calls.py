"""Running a model for its evaluator's task: each task's call, and the checks on what comes back.

The evaluator names the task (``Evaluator.task``); :func:`model_outputs` runs the model on a
batch of stored images and returns what that task's evaluator reads (see
:mod:`sweep3d.stages.infer.outputs`), or raises a one-line :class:`UserError` naming the model.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from sweep3d.core import PLUGIN_FAILURES, UserError, from_uint8, plugin_failure
from sweep3d.stages.infer import outputs
from sweep3d.stages.infer.cam import cam_localize, supports_cam
from sweep3d.stages.infer.evaluators.evaluator import TASKS
from sweep3d.stages.infer.models import Classifier, Detector, Preprocess, Segmenter, on_device, preprocessed
from sweep3d.stages.infer.outputs import Localized


def predict(model: Classifier, images: np.ndarray, name: str = "the model", runner: Callable | None = None) -> np.ndarray:
    """Logits of a batch.

    Args:
        images: float32 (N, H, W, 3) in [0, 1], or their uint8 pixels.
        name: the model's name in the spec, for error messages.
        runner: runs the preprocessed batch instead of the torch module (e.g. ONNX Runtime).
    Returns:
        float32 (N, C) logits.
    Raises:
        UserError: if the model raises or its output is not (N, C).
    """
    out = _call(model, images, name, runner)
    if isinstance(out, (tuple, list)):
        out = out[0]
    if hasattr(out, "detach"):  # a torch tensor
        out = out.detach().float().cpu().numpy()
    if not isinstance(out, np.ndarray) or out.ndim != 2 or out.shape[0] != len(images):
        shape = tuple(out.shape) if isinstance(out, np.ndarray) else type(out).__name__
        raise UserError(f"the model must return logits of shape (batch, classes); got {shape}")
    return out.astype(np.float32, copy=False)


def model_outputs(model: Classifier, images: np.ndarray, task: str, name: str,
                  runner: Callable | None = None) -> Any:
    """What ``task``'s evaluator reads, for a batch of stored images (N, H, W, 3): float32 in
    [0, 1], or their uint8 pixels."""
    if task == "classification":
        return predict(model, images, name, runner)
    if images.dtype == np.uint8:
        images = from_uint8(images)
    if task == "localization":
        return localize(model, images, name)
    if task == "detection":
        found = outputs.detections_from(_call(model, images, name), len(images), len(model.label_map()), name)
        if isinstance(model.preprocess, Preprocess):  # boxes in the resized crop: back to the image
            h, w = images.shape[1:3]
            found = [type(d)(model.preprocess.to_image(d.boxes, h, w), d.labels, d.scores) for d in found]
        return found
    if task == "segmentation":
        return outputs.segment_scores_from(_call(model, images, name), len(images), len(model.label_map()),
                                   tuple(images.shape[1:3]), name)
    out = _call(model, images, name)  # "raw": the evaluator reads the model's own output
    out = out.detach().float().cpu().numpy() if hasattr(out, "detach") else np.asarray(out)
    if out.ndim == 0 or out.shape[0] != len(images):
        raise UserError(f"model {name!r} must return one output per image (first axis {len(images)}); "
                        f"got shape {tuple(out.shape)}")
    return out


def localize(model: Classifier, images: np.ndarray, name: str) -> Localized:
    """Logits and one box per image, in the stored image's pixels: from the model's class
    activation map (EfficientNet and any module with ``extract_features`` and ``_fc``), else
    from a module that returns ``(logits (N, C), boxes (N, 4))`` in its input's pixels."""
    import torch

    if supports_cam(model.module):
        try:
            with torch.inference_mode():
                logits, boxes = cam_localize(model.module, on_device(model.module, model.preprocess(images)))
        except PLUGIN_FAILURES as exc:  # a user's module failing on its input is a user error
            raise _raised(name, exc, images) from None
    else:
        out = _call(model, images, name)
        if not (isinstance(out, (tuple, list)) and len(out) == 2):
            raise UserError(f"model {name!r} cannot localize: give it extract_features and a final linear _fc "
                            "(a class activation map), or return (logits, boxes) per batch")
        logits, boxes = (np.asarray(o.detach().float().cpu().numpy() if hasattr(o, "detach") else o, np.float64)
                         for o in out)
        if logits.ndim != 2 or logits.shape[0] != len(images) or boxes.shape != (len(images), 4):
            raise UserError(f"model {name!r} must return logits (batch, classes) and boxes (batch, 4); "
                            f"got {logits.shape} and {boxes.shape}")
    if isinstance(model.preprocess, Preprocess):
        boxes = model.preprocess.to_image(boxes, *images.shape[1:3])
    return Localized(np.asarray(logits, np.float32), np.asarray(boxes, np.float64))


def check_task(model: Classifier, task: str, name: str) -> None:
    """Refuse a model that cannot answer ``task`` (a classifier asked to detect, ...), and a task
    that is none of :data:`TASKS` (a user's evaluator would otherwise get the raw output)."""
    if task not in TASKS:
        raise UserError(f"the evaluator asks for task {task!r}; an evaluator's task is one of {', '.join(TASKS)}")
    wanted = {"detection": Detector, "segmentation": Segmenter}.get(task)
    if wanted is not None and not isinstance(model, wanted):
        raise UserError(f"evaluator kind {task!r} needs a {wanted.__name__} but model {name!r} is a "
                        f"{type(model).__name__}; return sweep3d.stages.infer.{wanted.__name__}(...) from its factory")
    if task in ("classification", "localization") and isinstance(model, (Detector, Segmenter)):
        raise UserError(f"model {name!r} is a {type(model).__name__}; evaluator kind {task!r} needs a classifier "
                        f"(use kind = {'detection' if isinstance(model, Detector) else 'segmentation'!r})")


def _call(model: Classifier, images: np.ndarray, name: str, runner: Callable | None = None) -> Any:
    """The module's (or ``runner``'s) output on the preprocessed batch; its failure as a UserError.
    A runner (ONNX Runtime) is called without torch, which it imports only if it needs it."""
    try:
        if runner is not None:
            return runner(preprocessed(model.preprocess, images))
        import torch

        with torch.inference_mode():
            batch = preprocessed(model.preprocess, images)
            if isinstance(batch, np.ndarray):
                batch = torch.from_numpy(batch)
            return model.module(on_device(model.module, batch))
    except PLUGIN_FAILURES as exc:  # a user's model failing on its input (or exiting) is a user error
        raise _raised(name, exc, images) from None


def _raised(name: str, exc: BaseException, images: np.ndarray) -> UserError:
    if isinstance(exc, SystemExit):
        return plugin_failure(f"model {name!r}", exc, during=f"on a batch of shape {tuple(images.shape)}")
    detail = " ".join(str(exc).split())[:300]
    return UserError(f"model {name!r} raised {type(exc).__name__} on a batch of shape {tuple(images.shape)}: "
                     f"{detail}; fix the model or its preprocessing")
