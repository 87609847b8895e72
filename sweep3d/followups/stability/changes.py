"""The changes no eye sees that the stability check makes to an image, and the margin it reads.

Each change is small enough that a person comparing the images would call them the same, yet the
kind of thing two faithful implementations of one protocol differ by:

``noise``
    ±1 level (of 255) on 10 % of the pixels, all three channels of a pixel the same way, clipped
    to 0..255.
``dither``
    Blender's dither toggled, emulated on the stored 8-bit image (the float render is gone):
    the lost fraction of each value is drawn uniformly, dither's noise of ±0.5 level is added and
    the sum rounded again. On a smooth render that changes about a quarter of the values by one
    level, as rendering with ``dither = 0`` instead of Blender's 1.0 does.
``resize``
    the model's bilinear resize computed in the other arithmetic (8-bit against float, see
    ``[model] resize_arithmetic``); only where the model resizes the image at all (not under
    ``resolution = "model"``, where the image is the model's input).

The random ones are seeded by (seed, image key, change), so a check is repeatable.
"""

from __future__ import annotations

import hashlib
from typing import Sequence

import numpy as np

#: The changes, in the order the check reports them.
CHANGES = ("noise", "dither", "resize")
#: The changes that draw random numbers (their keys name the seed).
RANDOM_CHANGES = frozenset({"noise", "dither"})
NOISE_FRACTION = 0.10  # of the pixels moved by one level


def change_rng(seed: int, image_key: str, change: str) -> np.random.Generator:
    """The generator of one change of one image under one seed."""
    word = hashlib.sha256(f"{seed}\0{image_key}\0{change}".encode()).digest()[:8]
    return np.random.default_rng(int.from_bytes(word, "little"))


def level_noise(pixels: np.ndarray, rng: np.random.Generator, fraction: float = NOISE_FRACTION) -> np.ndarray:
    """``pixels`` (uint8 (H, W, 3)) with ``fraction`` of the pixels one level up or down."""
    h, w = pixels.shape[:2]
    chosen = rng.random((h, w)) < fraction
    step = np.where(rng.random((h, w)) < 0.5, -1, 1) * chosen
    return np.clip(pixels.astype(np.int16) + step[..., None], 0, 255).astype(np.uint8)


def toggled_dither(pixels: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``pixels`` (uint8) quantised again with Blender's dither (±0.5 level of uniform noise before
    rounding) from a float image whose lost fraction is drawn uniformly."""
    lost = rng.random(pixels.shape) - 0.5
    dither = rng.random(pixels.shape) - 0.5
    return np.clip(np.floor(pixels.astype(np.float64) + lost + dither + 0.5), 0, 255).astype(np.uint8)


def changed(pixels: np.ndarray, change: str, seed: int, image_key: str) -> np.ndarray:
    """The image as ``change`` makes it (``resize`` changes the model's arithmetic, not the pixels)."""
    if change == "noise":
        return level_noise(pixels, change_rng(seed, image_key, change))
    if change == "dither":
        return toggled_dither(pixels, change_rng(seed, image_key, change))
    return pixels


def margins(logits: np.ndarray, truths: Sequence[Sequence[int]]) -> np.ndarray:
    """Each image's best true class's probability minus its best other class's (float64 (N,)),
    exact from the logits: the same quantity ``results.margin`` reads from the stored top-k. A
    missing side (no true class, or no other class) counts as probability 0; a row with
    non-finite logits gives NaN, which callers treat as invalid (never stored as a margin)."""
    x = np.asarray(logits, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        shifted = x - x.max(axis=1, keepdims=True)
        p = np.exp(shifted)
        p /= p.sum(axis=1, keepdims=True)
    out = np.empty(len(x))
    for i, ids in enumerate(truths):
        mask = np.zeros(x.shape[1], dtype=bool)
        mask[list(ids)] = True
        true = p[i, mask].max() if mask.any() else 0.0
        other = p[i, ~mask].max() if (~mask).any() else 0.0
        out[i] = true - other
    return out
