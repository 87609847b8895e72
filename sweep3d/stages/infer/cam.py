"""Boxes from class activation maps: a classifier turned localizer with no extra weights.

For a network that ends in global average pooling and one linear layer (the EfficientNet
family), the top-1 class's logit is the average over positions of its *class activation map*:
the last convolutional features weighted by that class's row of the linear layer (Zhou et al.,
"Learning Deep Features for Discriminative Localization", 2016). Upsampled to the input, the
map is kept where it reaches :data:`THRESHOLD` of its maximum, and the box of its largest
connected region is the answer — that paper's recipe, which needs no training.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: The share of the map's maximum a pixel needs to be kept (the paper's 20 %).
THRESHOLD = 0.2


def supports_cam(module: Any) -> bool:
    """Whether ``module`` exposes what a CAM needs: ``extract_features`` and a final linear ``_fc``."""
    return callable(getattr(module, "extract_features", None)) and hasattr(getattr(module, "_fc", None), "weight")


def cam_localize(module: Any, batch: Any) -> tuple[np.ndarray, np.ndarray]:
    """Logits (N, C) and each image's top-1 box (N, 4) in the input's pixels (a NaN row where
    the map is flat), for a preprocessed ``batch`` (N, 3, H, W).

    The logits are the module's own: the pooled features through its linear layer, as its
    forward pass computes them in eval mode.
    """
    import torch
    import torch.nn.functional as F

    with torch.inference_mode():
        features = module.extract_features(batch)  # (N, K, h, w)
        logits = module._fc(features.mean(dim=(2, 3)))
        top1 = logits.argmax(dim=1)
        weights = module._fc.weight[top1]  # (N, K)
        maps = torch.einsum("nk,nkhw->nhw", weights, features)
        maps = F.interpolate(maps[:, None], size=tuple(batch.shape[-2:]), mode="bilinear", align_corners=False)[:, 0]
    boxes = np.array([map_box(m) for m in maps.float().cpu().numpy()], dtype=np.float64).reshape(-1, 4)
    return logits.float().cpu().numpy(), boxes


def map_box(activation: np.ndarray, threshold: float = THRESHOLD) -> tuple[float, float, float, float]:
    """The box (x0, y0, x1, y1) of the largest connected region of ``activation`` at or above
    ``threshold`` × its maximum; NaNs when the map has no positive maximum or is not finite."""
    from scipy import ndimage

    peak = float(np.max(activation)) if activation.size else 0.0
    if not np.isfinite(activation).all() or peak <= 0:
        return (np.nan,) * 4
    regions, count = ndimage.label(activation >= threshold * peak)
    sizes = np.bincount(regions.ravel(), minlength=count + 1)
    sizes[0] = 0
    ys, xs = np.nonzero(regions == int(np.argmax(sizes)))
    return float(xs.min()), float(ys.min()), float(xs.max() + 1), float(ys.max() + 1)
