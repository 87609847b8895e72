"""What models return, per task, checked before any evaluator sees it.

A model's raw output is turned into one of these (or refused with a one-line error naming the
model and what is wrong), so evaluators only ever see well-formed, finite outputs:

- classification: logits, float (N, C);
- localization: :class:`Localized`, logits and one box per image;
- detection: one :class:`Detections` per image (torchvision's convention: a list of dicts with
  ``boxes`` (K, 4) as ``x0, y0, x1, y1`` pixels, ``labels`` (K,), ``scores`` (K,));
- segmentation: class scores, float (N, C, H, W) in the stored image's pixel grid.

Boxes are in the stored image's pixels, continuous coordinates from its top-left corner.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from sweep3d.core import UserError


@dataclass(frozen=True, eq=False)
class Localized:
    """A localizer's answer for a batch: class logits (N, C) and one box per image (N, 4),
    float64, a row of NaN where it found none."""

    logits: np.ndarray
    boxes: np.ndarray


@dataclass(frozen=True, eq=False)
class Detections:
    """One image's detections: ``boxes`` float64 (K, 4), ``labels`` int64 (K,) ids of the
    detector's label map, ``scores`` float64 (K,); K may be 0."""

    boxes: np.ndarray
    labels: np.ndarray
    scores: np.ndarray


def detections_from(output: Any, n: int, classes: int, name: str) -> list[Detections]:
    """A detector's output for a batch of ``n`` images as one :class:`Detections` per image.

    Torchvision's convention: a list (or tuple) of ``n`` dicts with ``boxes`` (K, 4) as
    ``x0, y0, x1, y1`` pixels, ``labels`` (K,) class ids and ``scores`` (K,); torch tensors or
    numpy arrays. Checked here, once, so a broken detector stops the run with one line instead of
    filling the store with rows that look like misses.

    Raises:
        UserError: naming the model, what is wrong and how to fix it.
    """
    where = f"detector {name!r}"
    fix = "return torchvision's format: a list of one dict per image with boxes (K, 4), labels (K,), scores (K,)"
    if not isinstance(output, (list, tuple)) or len(output) != n:
        got = f"a {type(output).__name__}" + (f" of {len(output)}" if isinstance(output, (list, tuple)) else "")
        raise UserError(f"{where} returned {got} for a batch of {n} images; {fix}")
    out = []
    for i, item in enumerate(output):
        if not isinstance(item, Mapping):
            raise UserError(f"{where} returned a {type(item).__name__} for image {i}, not a dict; {fix}")
        missing = [key for key in ("boxes", "labels", "scores") if key not in item]
        if missing:
            raise UserError(f"{where} returned no {', '.join(missing)} for image {i}; {fix}")
        out.append(_checked_detections(*(_numpy(item[key]) for key in ("boxes", "labels", "scores")),
                                       classes, f"{where} image {i}", fix))
    return out


def _checked_detections(boxes: np.ndarray, labels: np.ndarray, scores: np.ndarray, classes: int,
                        where: str, fix: str) -> Detections:
    """One image's arrays, checked for shape, finiteness, class range and box orientation."""
    if boxes.size == 0 and labels.size == 0 and scores.size == 0:
        boxes = boxes.reshape(0, 4)  # an empty image's (0,) boxes are as good as (0, 4)
    if boxes.ndim != 2 or boxes.shape[1] != 4:
        raise UserError(f"{where}: boxes have shape {boxes.shape}, not (K, 4); {fix}")
    k = boxes.shape[0]
    for key, values in (("labels", labels), ("scores", scores)):
        if values.shape != (k,):
            raise UserError(f"{where}: {key} have shape {values.shape} for {k} boxes, not ({k},); {fix}")
    boxes, scores = boxes.astype(np.float64), scores.astype(np.float64)
    for key, values in (("boxes", boxes), ("scores", scores)):
        if not np.all(np.isfinite(values)):
            raise UserError(f"{where}: {key} hold NaN or inf; fix the model (or drop those detections)")
    if labels.dtype.kind not in "iub" and not np.array_equal(labels, np.round(labels)):
        raise UserError(f"{where}: labels are not whole numbers; return class ids (int64)")
    ids = labels.astype(np.int64)
    if k and (ids.min() < 0 or ids.max() >= classes):
        bad = int(ids[(ids < 0) | (ids >= classes)][0])
        raise UserError(f"{where}: label {bad} is outside 0..{classes - 1} (the label map has {classes} classes); "
                        "give the detector the label map its ids index")
    if np.any(boxes[:, 2] < boxes[:, 0]) or np.any(boxes[:, 3] < boxes[:, 1]):
        raise UserError(f"{where}: a box has x1 < x0 or y1 < y0; return boxes as (x0, y0, x1, y1) pixels")
    return Detections(boxes=boxes, labels=ids, scores=scores)


def segment_scores_from(output: Any, n: int, classes: int, size: tuple[int, int], name: str) -> np.ndarray:
    """A segmenter's output as float32 class scores (N, C, H, W) at the stored image's ``size`` (H, W).

    Accepts the scores themselves or torchvision's dict (``{"out": scores, ...}``). Scores at another
    resolution are resized bilinearly, so the evaluator compares them with the mask pixel for
    pixel. Non-finite scores pass: the evaluator marks that image invalid, the others still count.

    Raises:
        UserError: on a missing ``out``, or scores that are not (n, classes, h, w).
    """
    where = f"segmenter {name!r}"
    if isinstance(output, Mapping):
        if "out" not in output:
            raise UserError(f"{where} returned a dict without 'out' (keys: {', '.join(map(str, output))}); "
                            "return the class scores (N, C, H, W) or torchvision's {'out': scores}")
        output = output["out"]
    if not (hasattr(output, "shape") and hasattr(output, "ndim")):
        raise UserError(f"{where} returned a {type(output).__name__}, not class scores; "
                        "return a tensor (N, C, H, W) or torchvision's {'out': scores}")
    shape = tuple(int(s) for s in output.shape)
    if len(shape) != 4 or shape[0] != n or shape[1] != classes:
        raise UserError(f"{where} returned scores of shape {shape}; expected ({n}, {classes}, H, W): one score per "
                        f"class of its {classes}-class label map for each of the {n} images")
    if shape[2:] == tuple(size):
        return _numpy(output).astype(np.float32, copy=False)
    import torch

    tensor = output.detach() if hasattr(output, "detach") else torch.from_numpy(np.asarray(output))
    resized = torch.nn.functional.interpolate(tensor.float(), size=tuple(size), mode="bilinear", align_corners=False)
    return resized.cpu().numpy().astype(np.float32, copy=False)


def _numpy(value: Any) -> np.ndarray:
    """A tensor (torch or anything with ``.detach().cpu().numpy()``) or array-like as numpy, without importing torch."""
    if hasattr(value, "detach"):
        value = value.detach().cpu()
        try:
            value = value.numpy()
        except TypeError:  # a dtype numpy lacks (bfloat16): as float32
            value = value.float().numpy()
    return np.asarray(value)
