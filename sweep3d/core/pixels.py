"""Image blobs: float32 RGB arrays in [0, 1] to and from 8-bit PNG bytes."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image


def to_uint8(rgb: np.ndarray) -> np.ndarray:
    """Quantise a float image (round half up after clipping to [0, 1]); NaN becomes 0, +inf 255
    (callers flag non-finite images before this). One copy, then in place: it runs once per
    post-processed image, so its passes over the image count (benchmarks/RESULTS.md, issue 37)."""
    scaled = np.clip(rgb, 0.0, 1.0)  # +inf → 1, -inf → 0; NaN stays NaN
    scaled *= 255.0
    scaled += 0.5
    scaled[np.isnan(scaled)] = 0.0
    return scaled.astype(np.uint8)


def from_uint8(pixels: np.ndarray) -> np.ndarray:
    """8-bit pixels as float32 in [0, 1]: exactly what :func:`decode_png` gives for their PNG."""
    return pixels.astype(np.float32) / np.float32(255.0)


def encode_png(rgb: np.ndarray) -> bytes:
    """PNG bytes of a float32 (H, W, 3) image."""
    return encode_png8(to_uint8(rgb))


def encode_png8(pixels: np.ndarray) -> bytes:
    """PNG bytes of a uint8 (H, W, 3) image (fast compression: blobs are written once, read rarely)."""
    buf = io.BytesIO()
    Image.fromarray(pixels, "RGB").save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def png_size(data: bytes) -> tuple[int, int]:
    """Width and height of PNG bytes, from their header (nothing is decoded)."""
    if data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
        raise ValueError("not a PNG")
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def decode_png(path: str | Path) -> np.ndarray:
    """A PNG file as float32 (H, W, 3) in [0, 1]."""
    return from_uint8(decode_png8(path))


def decode_png8(path: str | Path | io.BytesIO) -> np.ndarray:
    """A PNG file (or its bytes in a file object) as its uint8 (H, W, 3) RGB pixels."""
    with Image.open(path) as img:
        return np.asarray(img if img.mode == "RGB" else img.convert("RGB"), dtype=np.uint8)


def srgb_to_linear(rgb: np.ndarray) -> np.ndarray:
    """sRGB-encoded values (what the renderer's Standard view transform stores) as linear light,
    float32: the inverse of :func:`linear_to_srgb`. Values are clipped to [0, 1] first."""
    c = np.clip(np.asarray(rgb, dtype=np.float32), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(rgb: np.ndarray) -> np.ndarray:
    """Linear light as sRGB-encoded values in [0, 1], float32 (the piecewise sRGB curve)."""
    c = np.clip(np.asarray(rgb, dtype=np.float32), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055).astype(np.float32)
