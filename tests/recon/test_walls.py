"""Tests of recon.walls: the walls across a trace and centring on the wall that stayed."""

from __future__ import annotations

import numpy as np
import pytest

from recon.walls import one_wall_shifts, reference_width, wall_offsets


def _tube_image(radius_px: float, shape: tuple[int, int] = (60, 80)) -> np.ndarray:
    """Absorption image (vessel bright) of a horizontal tube at row 30: chord length."""
    rows = np.arange(shape[0], dtype=float)[:, None] * np.ones(shape[1])[None, :]
    return 2.0 * np.sqrt(np.clip(radius_px**2 - (rows - 30.0) ** 2, 0.0, None))


def test_wall_offsets_find_both_walls_of_a_tube() -> None:
    img = _tube_image(6.0)
    pts = np.column_stack([np.arange(20.0, 60.0), np.full(40, 30.4)])  # 0.4 px off centre
    normals = np.tile([0.0, 1.0], (40, 1))
    left, right = wall_offsets(img, pts, normals, np.full(40, 6.0))
    # the steepest slopes of the smoothed chord profile lie just inside its edges
    # (-6.4, +5.6), by the same amount on both sides: their midpoint is the centre
    assert np.all((left > -6.4) & (left < -5.4)) and np.all((right < 5.6) & (right > 4.6))
    assert np.allclose(0.5 * (left + right), -0.4, atol=0.05)


def test_wall_offsets_are_nan_where_no_wall_is_in_reach() -> None:
    img = np.zeros((60, 80))
    pts = np.column_stack([np.arange(20.0, 30.0), np.full(10, 30.0)])
    left, right = wall_offsets(img, pts, np.tile([0.0, 1.0], (10, 1)), np.full(10, 4.0))
    assert np.all(np.isnan(left)) and np.all(np.isnan(right))


def test_reference_width_is_not_pulled_by_an_overlap_in_the_middle() -> None:
    width = np.full(300, 8.5)
    width[100:200] = 14.4  # a third of the trace: the running median alone follows it
    ref = reference_width(width, np.ones(300, dtype=bool))
    assert np.all((ref >= 8.5) & (ref < 8.5 * 1.06))  # at most the trend + 5 %


def test_one_wall_shifts_centres_on_the_wall_that_stayed() -> None:
    rng = np.random.default_rng(0)
    n = 300
    left = -4.2 + rng.normal(0.0, 0.05, n)
    right = 4.2 + rng.normal(0.0, 0.05, n)
    shift = rng.normal(0.0, 0.05, n)
    left[100:200] = -10.2  # a neighbour overlaps the left side: one wide tube
    shift[100:200] = -2.0  # the profile fit moved towards it
    left[220:240] = -4.9  # a neighbour just beyond the left wall, inside the fit's window
    shift[220:240] = -1.5
    new, done = one_wall_shifts(shift, left, right, np.ones(n, dtype=bool))
    assert np.all(done[100:200]) and np.all(done[220:240])
    # half the reference width inside the right wall: 4.2 + 5 % (the cap's least margin
    # over the trend of 8.4), so -0.21 px, within the walls' noise
    assert np.all(np.abs(new[100:200] + 0.21) < 0.25)
    assert np.all(np.abs(new[220:240] - (-0.35)) < 0.2)  # the walls' midpoint
    assert not np.any(done[:90]) and not np.any(done[250:])
    np.testing.assert_array_equal(new[:90], shift[:90])


@pytest.mark.parametrize("moved", ["both", "inward"])
def test_one_wall_shifts_leaves_a_crossing_or_a_narrowing_alone(moved: str) -> None:
    n = 300
    left, right, shift = np.full(n, -4.2), np.full(n, 4.2), np.zeros(n)
    if moved == "both":  # a vessel crossing over covers both walls
        left[140:160], right[140:160] = -9.0, 9.0
    else:  # a lesion: the walls move in
        left[140:160], right[140:160] = -2.0, 2.5
    shift[140:160] = 0.25
    new, done = one_wall_shifts(shift, left, right, np.ones(n, dtype=bool))
    assert not np.any(done)
    np.testing.assert_array_equal(new, shift)
