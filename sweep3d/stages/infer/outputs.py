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

from dataclasses import dataclass

import numpy as np


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
