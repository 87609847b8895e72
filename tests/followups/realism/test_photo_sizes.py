"""Which photographs can be framed as their render (issue 45, item 7): framing shrinks, never
enlarges, so one smaller than its render either way is refused, naming the minimum; and which
are too large to read (more than :data:`MAX_PIXELS`, judged from the header)."""

from __future__ import annotations

from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st

from sweep3d.followups.realism.photos import MAX_PIXELS, framed, too_small, unreadable
from tests.helpers.bad_inputs import plain_png, png_header

SIDES = st.integers(1, 4096)


@given(photo=st.tuples(SIDES, SIDES), render=st.tuples(SIDES, SIDES))
def test_a_photograph_is_refused_exactly_when_framing_would_enlarge_it(photo: tuple[int, int],
                                                                       render: tuple[int, int]) -> None:
    (h, w), (rh, rw) = photo, render
    enlarges = max(rh / h, rw / w) > 1  # the scale framed() resizes by
    why = too_small(photo, render)
    assert bool(why) == enlarges
    if why:
        assert f"is {w}×{h} pixels, smaller than its render ({rw}×{rh})" in why and f"at least {rw}×{rh}" in why


def test_framing_the_smallest_allowed_photograph_keeps_its_pixels() -> None:
    import numpy as np

    pixels = np.random.default_rng(0).integers(0, 256, (24, 40, 3), dtype=np.uint8)
    assert not too_small(pixels.shape[:2], (24, 40)) and np.array_equal(framed(pixels, 24, 40), pixels)


def test_the_size_limit_is_judged_from_the_header(tmp_path: Path) -> None:
    side = int(MAX_PIXELS ** 0.5)
    at_limit, past = tmp_path / "at.png", tmp_path / "past.png"
    at_limit.write_bytes(png_header(side, side))  # not too large: read on, and found truncated
    past.write_bytes(png_header(side + 1, side + 1))
    assert unreadable(at_limit).startswith("cannot be decoded"), unreadable(at_limit)
    assert unreadable(past).startswith(f"is too large ({side + 1}×{side + 1} pixels"), unreadable(past)
    small = tmp_path / "small.png"
    small.write_bytes(plain_png(3, 2))
    assert unreadable(small) == ""
