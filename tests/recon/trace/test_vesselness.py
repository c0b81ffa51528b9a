"""Tests of recon.trace.vesselness: scales in millimetres, pyramid levels, and a ridge
measure that does not depend on the vessel's contrast."""

from __future__ import annotations

import numpy as np
import pytest
from test_intensity import path_length, xray

from recon.trace.vesselness import (
    DEFAULT_SIGMAS_PX,
    RADIUS_PER_SIGMA,
    compute_vesselness,
    sigmas_for_pixel,
)
from recon.trace.vesselness import _level_for as level_for

#: Pixel size at the vessel of a 0.154 mm flat detector at magnification 976 / 720.
FINE_PIXEL_MM = 0.154 * 720.0 / 976.0


def segment(p, q, n=3000):
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.asarray(p, float) * (1 - t) + np.asarray(q, float) * t


def test_scales_follow_the_pixel_size() -> None:
    assert sigmas_for_pixel(None) == DEFAULT_SIGMAS_PX
    for pixel_mm in (0.4 * 720 / 976, 0.2, FINE_PIXEL_MM):
        s = np.array(sigmas_for_pixel(pixel_mm))
        assert s[0] >= 1.0 and np.all(np.diff(s) > 0)
        assert np.all(s[1:] / s[:-1] <= np.sqrt(2.0) + 1e-9)
        # a 3 mm lumen radius is covered; a 0.25 mm one is not below the first scale
        assert RADIUS_PER_SIGMA * s[-1] * pixel_mm == pytest.approx(3.0, rel=1e-6)
        assert s[0] == pytest.approx(max(1.0, 0.25 / pixel_mm / RADIUS_PER_SIGMA))
    with pytest.raises(ValueError, match="pixel_mm"):
        sigmas_for_pixel(-1.0)


def test_large_scales_run_on_coarse_pyramid_levels() -> None:
    """A 1024 x 1024 image at 0.114 mm/px needs scales up to ~22 px; every scale
    above 3 px is computed on a level at least 2x coarser, and no level sees a
    scale of more than ~3 of its pixels, so the work per scale shrinks 4x per level."""
    sigmas = sigmas_for_pixel(FINE_PIXEL_MM)
    assert max(sigmas) > 20.0
    levels = [level_for(s) for s in sigmas]
    assert sum(lv == 0 for lv in levels) <= 2
    assert all(s / 2**lv < 3.0 for s, lv in zip(sigmas, levels, strict=True))
    # Pixels processed (summed over scales) against the former filter, which ran
    # its 5 scales on every pixel of a 512 x 512 image: about 2x.
    pixels_1024 = sum(1024**2 / 4**lv for lv in levels)
    assert pixels_1024 <= 2.2 * 5 * 512**2


def test_ridge_is_contrast_invariant_and_response_is_per_image() -> None:
    strong, faint = segment((10, 30), (150, 30)), segment((10, 90), (150, 90))
    length = path_length((120, 160), strong, 3.0) + 0.15 * path_length((120, 160), faint, 3.0)
    img = xray(length, "lin", mu=0.1)  # the faint vessel: 15 % of the strong one's iodine
    vmap = compute_vesselness(img)
    strong_ridge = vmap.ridge[28:33, 40:120].max(axis=0)
    faint_ridge = vmap.ridge[88:93, 40:120].max(axis=0)
    assert faint_ridge.min() > 0.75 and strong_ridge.min() > 0.75
    assert np.median(faint_ridge) > 0.9 * np.median(strong_ridge)
    assert vmap.response[88:93, 40:120].max() < 0.5 * vmap.response[28:33, 40:120].max()
    # the ridge's scale says the radius, for both
    for rows in (slice(28, 33), slice(88, 93)):
        sub = vmap.ridge[rows, 40:120]
        r = RADIUS_PER_SIGMA * vmap.scale_px[rows, 40:120][sub == sub.max(axis=0)]
        assert np.median(r) == pytest.approx(3.0, rel=0.4)  # a guess for the fit's window
    assert vmap.direction_rad is not None
    angle = vmap.direction_rad[30, 40:120]
    assert np.all(np.minimum(angle, np.pi - angle) < 0.1)  # along the columns


def test_a_wide_vessel_answers_at_its_centre_at_fine_pixels() -> None:
    """35 px wide at 0.114 mm/px (a 4 mm left main): the strongest ridge centre is on
    its axis, not at its two edges."""
    line = segment((20, 100), (300, 100))
    img = xray(path_length((200, 320), line, 17.5, ss=2), "lin", mu=0.02)
    vmap = compute_vesselness(img, pixel_mm=FINE_PIXEL_MM)
    assert vmap.pixel_mm == pytest.approx(FINE_PIXEL_MM)
    col = vmap.strength[60:141, 160]
    assert abs(60 + int(np.argmax(col)) - 100) <= 0.25 * 17.5  # the fit re-centres
    assert RADIUS_PER_SIGMA * vmap.scale_px[100, 160] == pytest.approx(17.5, rel=0.3)


def test_bitwise_selection_is_np_where_to_the_bit() -> None:
    """The per-pixel selections (recon.trace.vesselness._select_into, _zero_outside) give
    np.where's float32 bits, signed zeros, infinities and NaN included."""
    from recon.trace.vesselness import _mask32, _select_into, _zero_outside

    rng = np.random.default_rng(3)
    special = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 1e-45, -1.0], np.float32)
    x = np.concatenate([rng.standard_normal(500).astype(np.float32), special])
    y = np.concatenate([rng.standard_normal(500).astype(np.float32), special[::-1]])
    cond = rng.random(x.size) < 0.5
    got = x.copy()
    _select_into(got, y, _mask32(cond))
    assert np.array_equal(got.view(np.uint32), np.where(cond, y, x).view(np.uint32))
    zeroed = _zero_outside(y.copy(), _mask32(cond))
    assert np.array_equal(zeroed.view(np.uint32),
                          np.where(cond, y, np.float32(0.0)).view(np.uint32))


def test_the_stronger_layer_wins_and_ties_keep_the_first() -> None:
    from recon.trace.vesselness import _keep_stronger

    first = [np.array([1.0, 2.0, 3.0], np.float32) for _ in range(9)]
    dst = [np.empty(3, np.float32) for _ in range(9)]
    _keep_stronger(dst, first[:8], first[8], True)
    strength = np.array([0.5, 2.0, 4.0], np.float32)  # weaker, tied, stronger
    other = [strength, 7.0, *(np.full(3, 9.0, np.float32) for _ in range(6))]
    _keep_stronger(dst, other, np.array([0.0, 5.0, 1.0], np.float32), False)
    assert dst[0].tolist() == [1.0, 2.0, 4.0]
    assert dst[1].tolist() == [1.0, 2.0, 7.0]  # a scalar layer (the scale) broadcast
    assert all(d.tolist() == [1.0, 2.0, 9.0] for d in dst[2:8])
    assert dst[8].tolist() == [1.0, 5.0, 3.0]  # the junction measure: the larger
