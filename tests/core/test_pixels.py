"""8-bit pixels: quantising a float image, and reading a PNG back as pixels or floats."""

from __future__ import annotations

import io

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from sweep3d.core.pixels import decode_png, decode_png8, encode_png8, from_uint8, to_uint8
from tests.helpers import examples

_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=32),
                    st.floats(-0.25, 1.25, width=32), st.sampled_from([0.5, 127.5, 254.5]).map(lambda v: float(np.float32(v) / np.float32(255))))


@settings(max_examples=examples(300), deadline=None)
@given(image=hnp.arrays(np.float32, (3, 4, 3), elements=_VALUES), wide=st.booleans())
def test_quantising_rounds_half_up_after_clipping_nan_to_0_and_leaves_the_input(image, wide) -> None:
    """Each value is round(clip(v, 0, 1) · 255) with halves up, in the image's own float type; NaN
    is 0, +inf 255, −inf 0 (what the stored PNG of a flagged image holds); the input is not changed."""
    image = image.astype(np.float64) if wide else image
    before = image.copy()
    got = to_uint8(image)
    clean = np.nan_to_num(image, nan=0.0, posinf=1.0, neginf=0.0)
    expected = np.floor(np.clip(clean, 0.0, 1.0) * image.dtype.type(255.0) + image.dtype.type(0.5)).astype(np.uint8)
    assert got.dtype == np.uint8 and np.array_equal(got, expected)
    assert np.array_equal(before, image, equal_nan=True)


@settings(max_examples=examples(50), deadline=None)
@given(pixels=hnp.arrays(np.uint8, (5, 7, 3)))
def test_a_png_reads_back_as_its_pixels_and_as_floats_that_quantise_to_them(pixels) -> None:
    data = encode_png8(pixels)
    assert np.array_equal(decode_png8(io.BytesIO(data)), pixels)
    floats = decode_png(io.BytesIO(data))
    assert floats.dtype == np.float32 and np.array_equal(floats, from_uint8(pixels))
    assert np.array_equal(to_uint8(floats), pixels)
