"""The parts layout (no Blender): directions to parts, the seam, and counting a UV pass."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from sweep3d.core.uv_cells import (
    AZIMUTH_PARTS,
    ELEVATION_PARTS,
    PARTS,
    loop_uvs,
    part_bounds,
    part_counts,
    part_of,
    sphere_turns,
)
from tests.helpers import direction


def stored_uv(azimuth: float, elevation: float) -> tuple[np.ndarray, np.ndarray]:
    turns, band = sphere_turns(direction(azimuth, elevation))
    return turns / 2.0, band


def test_front_right_back_and_poles() -> None:
    assert np.allclose(sphere_turns(direction(0, 0)), ([0.5], [0.5]))
    assert np.allclose(sphere_turns(direction(90, 0)), ([0.75], [0.5]))
    assert np.allclose(sphere_turns(direction(-90, 0)), ([0.25], [0.5]))
    assert np.allclose(sphere_turns(direction(0, 90))[1], [1.0])
    assert np.allclose(sphere_turns(direction(0, -90))[1], [0.0])
    # the part just right of the front at the equator, and its bounds in degrees
    part = int(part_of(*stored_uv(10, 10))[0])
    assert part_bounds(part) == (0.0, 22.5, 0.0, 22.5)


@given(st.floats(-179.9, 179.9), st.floats(-89.9, 89.9))
def test_a_direction_lands_in_the_part_whose_bounds_hold_it(azimuth: float, elevation: float) -> None:
    part = int(part_of(*stored_uv(azimuth, elevation))[0])
    a0, a1, e0, e1 = part_bounds(part)
    tolerance = 1e-6
    assert a0 - tolerance <= azimuth <= a1 + tolerance and e0 - tolerance <= elevation <= e1 + tolerance


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=3, max_size=3))
def test_any_point_gets_a_finite_direction_and_a_valid_part(point: list[float]) -> None:
    azimuth, elevation = sphere_turns(np.array([point]))
    assert np.all(np.isfinite(azimuth)) and np.all(np.isfinite(elevation))
    assert 0.0 <= azimuth[0] < 1.0 and 0.0 <= elevation[0] <= 1.0
    assert 0 <= int(part_of(azimuth / 2, elevation)[0]) < PARTS


def test_a_face_across_the_back_seam_keeps_a_continuous_u() -> None:
    # a quad at the back (+Y) from azimuth 170° to -170°: the seam runs through it
    points = np.concatenate([direction(170, -5), direction(-170, -5), direction(-170, 5), direction(170, 5)])
    uvs = loop_uvs(points, np.array([0, 1, 2, 3]), np.array([0]))
    u = uvs[:, 0]
    assert u.max() - u.min() < 0.1, "interpolating across the face must not sweep the whole map"
    assert u.max() > 0.5  # the near side of the seam moved one turn on (stored u = turns / 2)
    slices = set((part_of(u, uvs[:, 1]) % AZIMUTH_PARTS).tolist())
    assert slices == {0, AZIMUTH_PARTS - 1}
    # a face away from the seam is left as it is
    front = np.concatenate([direction(-10, 0), direction(10, 0), direction(10, 10)])
    assert np.allclose(loop_uvs(front, np.array([0, 1, 2]), np.array([0]))[:, 0], sphere_turns(front)[0] / 2)


def test_counting_erodes_the_silhouette_and_counts_each_part() -> None:
    h = w = 12
    u, v = np.zeros((h, w)), np.zeros((h, w))
    mask = np.zeros((h, w), dtype=bool)
    mask[2:10, 2:10] = True  # 8×8 object: 6×6 inside once its rim is dropped
    u[:, :6], u[:, 6:] = stored_uv(-10, 0)[0][0], stored_uv(10, 0)[0][0]  # left half, right half
    v[:] = 0.5 + 1e-3
    seen = part_counts(u, v, mask)
    assert seen["object_pixels"] == 36
    left, right = (int(part_of(*stored_uv(a, 1))[0]) for a in (-10, 10))
    assert seen["parts"] == sorted([left, right]) and seen["pixels"] == [18, 18]
    assert part_counts(u, v, np.zeros((h, w), dtype=bool)) == {"parts": [], "pixels": [], "object_pixels": 0}
    thin = np.zeros((h, w), dtype=bool)
    thin[5, :] = True  # a one-pixel line is all silhouette
    assert part_counts(u, v, thin)["object_pixels"] == 0


def test_parts_cover_the_sphere_once() -> None:
    bounds = [part_bounds(p) for p in range(PARTS)]
    area = sum((a1 - a0) * (e1 - e0) for a0, a1, e0, e1 in bounds)
    assert area == 360 * 180 and len(set(bounds)) == PARTS == AZIMUTH_PARTS * ELEVATION_PARTS
