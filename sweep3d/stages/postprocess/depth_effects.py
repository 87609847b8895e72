"""The optics behind the depth-aware post controls, on plain arrays (no sweep3d types).

Both work in linear light: the stored image is sRGB-encoded (the renderer's Standard view
transform), and light adds up linearly, so each decodes, mixes, and encodes again.

Fog is Koschmieder's law for a homogeneous medium: a surface at ray distance d keeps
t = exp(-β d) of its radiance J and gains airlight A for the rest, I = J t + A (1 - t).

Defocus is a thin lens of aperture radius a focused at depth z_f: a point at depth z becomes a
disk of radius f_px · a · |1/z_f - 1/z| pixels (f_px: the focal length in pixels), as Cycles'
depth of field draws it (focal plane perpendicular to the axis, uniform round aperture). The
signed radius c = f_px · a · (1/z_f - 1/z) grows with depth, so quantising it sorts the image
into depth layers; each layer is blurred with its own disk (colour and coverage) and the layers
are laid far to near, each *over* what is behind it. So a sharp foreground keeps its edge over a
blurred background (it covers the background's spread), a blurred foreground spreads over a sharp
background, and no layer gathers colour from another. What a nearer layer hides, which its
blurred edge lets the lens see, is unknown: each layer is continued behind the nearer ones with
the colours around them (:func:`continued`), so a surface split into several layers closes up and
a blurred foreground shows the background that it hides.
"""

from __future__ import annotations

import numpy as np

from sweep3d.core import linear_to_srgb, srgb_to_linear

#: At most this many depth layers; their spacing in blur radius is at least :data:`LAYER_STEP` px.
MAX_LAYERS = 32
LAYER_STEP = 0.5
#: Sub-samples per pixel side when a disk kernel's edge pixels are given their covered area.
KERNEL_SUPERSAMPLING = 8


def fog(image: np.ndarray, distance: np.ndarray, density: float, airlight: np.ndarray) -> np.ndarray:
    """Koschmieder's fog over an sRGB ``image`` (float32 (H, W, 3) in [0, 1]).

    Args:
        distance: ray distance per pixel (H, W), ``inf`` for no surface (fully fogged).
        density: the extinction coefficient β (per unit of ``distance``), > 0.
        airlight: the fully fogged colour A, linear RGB (3,).
    """
    t = np.exp(-density * np.asarray(distance, dtype=np.float64))[..., None]  # exp(-inf) = 0
    linear = srgb_to_linear(image).astype(np.float64)
    return linear_to_srgb(linear * t + np.asarray(airlight, dtype=np.float64) * (1.0 - t))


def signed_coc(depth: np.ndarray, focus: float, focal_px: float, aperture: float) -> np.ndarray:
    """The signed blur radius in pixels per pixel, f_px · a · (1/z_f - 1/z), float64 (H, W).

    A non-finite or non-positive depth is no surface: at infinity, 1/z = 0 (a thin lens blurs
    infinity to a finite disk)."""
    depth = np.asarray(depth, dtype=np.float64)
    hit = np.isfinite(depth) & (depth > 0)
    inverse = np.where(hit, 1.0 / np.where(hit, depth, 1.0), 0.0)
    return focal_px * aperture * (1.0 / focus - inverse)


def disk_kernel(radius: float) -> np.ndarray:
    """A uniform disk of ``radius`` pixels, each pixel weighted by the part of it the disk covers,
    summing to 1 (float64, odd square)."""
    half = int(np.ceil(radius))
    # sub-samples per pixel and axis: fewer on a wide disk, whose edge pixels are a small share of it
    # (the grid has (2 · radius · s)² cells: a fixed s would take gigabytes at a few hundred pixels)
    s = max(1, min(KERNEL_SUPERSAMPLING, int(KERNEL_SUPERSAMPLING * 16 / max(radius, 1.0))))
    offsets = (np.arange(s) + 0.5) / s - 0.5
    grid = np.arange(-half, half + 1)
    fine = (grid[:, None] + offsets[None, :]).reshape(-1)  # every sub-sample coordinate, one axis
    inside = (fine[:, None] ** 2 + fine[None, :] ** 2) <= radius * radius
    kernel = inside.reshape(2 * half + 1, s, 2 * half + 1, s).mean(axis=(1, 3))
    if kernel.sum() == 0:  # a radius too small to cover a sub-sample: the identity
        kernel[half, half] = 1.0
    return kernel / kernel.sum()


def layers(coc: np.ndarray) -> tuple[np.ndarray, float]:
    """Each pixel's layer (an integer: its signed radius over the spacing, rounded) and the spacing
    (px): at least :data:`LAYER_STEP`, wider when the radii span more than :data:`MAX_LAYERS` of it.
    Layer 0 holds the pixels within half a spacing of the focal plane: they stay sharp."""
    span = float(coc.max() - coc.min()) if coc.size else 0.0
    step = max(LAYER_STEP, span / (MAX_LAYERS - 1))
    return np.rint(coc / step).astype(np.int64), step


def defocus(image: np.ndarray, coc: np.ndarray) -> np.ndarray:
    """A thin lens's blur of an sRGB ``image`` (float32 (H, W, 3)) given each pixel's signed blur
    radius ``coc`` (:func:`signed_coc`): depth layers blurred apart, composited far to near."""
    index, step = layers(coc)
    if not index.any():
        return image  # everything within the focal layer: nothing to blur
    from scipy.signal import fftconvolve  # here: importing scipy.signal costs every process ~1 s

    linear = srgb_to_linear(image).astype(np.float64)
    colour = np.zeros_like(linear)  # what lies behind the next layer: premultiplied colour ...
    cover = np.zeros(index.shape, dtype=np.float64)  # ... and its coverage
    for layer in np.unique(index)[::-1]:  # far (large signed radius) to near
        own, hidden = index == layer, index < layer  # its pixels, and those nearer layers hide it behind
        extent = own | hidden
        stack = np.concatenate([continued(linear, own, hidden) * extent[..., None], extent[..., None]], axis=-1)
        radius = abs(int(layer)) * step
        if radius > 0:
            stack = np.clip(fftconvolve(stack, disk_kernel(radius)[..., None], mode="same", axes=(0, 1)), 0.0, None)
        alpha = np.minimum(stack[..., 3], 1.0)
        colour = stack[..., :3] + (1.0 - alpha)[..., None] * colour
        cover = alpha + (1.0 - alpha) * cover
    return linear_to_srgb(colour / np.maximum(cover, 1e-12)[..., None])  # < 1 only near the image's edges


def continued(values: np.ndarray, known: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """``values`` (H, W, C) where ``known``, and at the ``wanted`` pixels that are not, what shows
    around them: normalised Gaussian blurs of the known values, of doubling width until each has
    one. A lens sees part of what a blurred foreground hides; the image never showed it, so each
    layer is taken to continue behind the nearer ones as it looks around them."""
    missing = wanted & ~known
    if not missing.any() or not known.any():
        return values
    from scipy.ndimage import gaussian_filter

    out = values.copy()
    weight = known.astype(np.float64)
    value = values * weight[..., None]
    sigma = 1.0
    while missing.any():
        total = gaussian_filter(weight, sigma, mode="nearest")
        reached = missing & (total > 1e-8)
        if reached.any():
            spread = gaussian_filter(value, (sigma, sigma, 0), mode="nearest")
            out[reached] = spread[reached] / total[reached][:, None]
            missing &= ~reached
        sigma *= 2.0
    return out
