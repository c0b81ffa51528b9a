"""The diameter chart (viewer_app.plot) from a small stand-in of a reconstruction."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from viewer_app.plot import profile_plot

CURVE = (30, 90, 200)  # the (smoothed) diameter
LESION_BAND = (255, 225, 225)


def _rec(smooth: bool) -> SimpleNamespace:
    s = np.linspace(0.0, 50.0, 201)
    d = 3.0 - 1.5 * np.exp(-(((s - 25.0) / 4.0) ** 2))
    profile = SimpleNamespace(s_mm=s, diameter_mm=d, reference_diameter_mm=np.full_like(s, 3.0))
    if smooth:
        profile.diameter_smooth_mm = d
    meas = {"mld_mm": 1.5, "mld_s_mm": 25.0, "lesion_start_s_mm": 18.0, "lesion_end_s_mm": 32.0}
    return SimpleNamespace(profile=profile, measurements=SimpleNamespace(to_dict=lambda: meas))


def _curve_rows(img: np.ndarray, col: int) -> np.ndarray:
    return np.flatnonzero(np.all(img[:, col] == CURVE, axis=-1))


def test_chart_is_an_rgb_image_with_the_diameter_curve() -> None:
    img = profile_plot(_rec(smooth=False))
    assert img.shape == (360, 640, 3) and img.dtype == np.uint8
    assert np.all(img[0, 0] == 255)  # white background
    assert np.count_nonzero(np.all(img == CURVE, axis=-1)) > 500
    assert np.any(np.all(img == LESION_BAND, axis=-1))
    # Same mapping as the chart: left 56, right 14, top 26, bottom 40 px; y to 1.15 x max.
    left, right, top, bottom, ymax = 56, 14, 26, 40, 3.0 * 1.15
    for s_mm in (5.0, 20.0, 40.0):  # (not at the MLD: its dot covers the curve)
        d_mm = 3.0 - 1.5 * np.exp(-(((s_mm - 25.0) / 4.0) ** 2))
        col = round(left + s_mm / 50.0 * (640 - left - right))
        row = 360 - bottom - d_mm / ymax * (360 - top - bottom)
        rows = _curve_rows(img, col)
        assert rows.size and abs(np.median(rows) - row) <= 2.0, (s_mm, rows, row)


def test_chart_size_and_smoothed_curve() -> None:
    img = profile_plot(_rec(smooth=True), width=400, height=240)
    assert img.shape == (240, 400, 3) and img.dtype == np.uint8
    assert np.count_nonzero(np.all(img == CURVE, axis=-1)) > 300


SITE = (90, 90, 90)  # the reference sites (dashed) and the straight reference
AREA = (20, 140, 120)


def test_reference_sites_are_drawn_where_the_clinician_put_them() -> None:
    rec = _rec(smooth=True)
    lesion = {"mld_mm": 1.5, "mld_s_mm": 25.0, "lesion_start_s_mm": 20.0,
              "lesion_end_s_mm": 30.0, "proximal_reference_mm": 3.0,
              "distal_reference_mm": 3.0, "proximal_reference_s_mm": 10.0,
              "distal_reference_s_mm": 40.0}
    img = profile_plot(rec, lesion=lesion)
    left, right = 56, 14

    def rows_in_site_colour(s_mm: float) -> int:
        """Rows of the chart where the 3 px column at s_mm has a pixel in SITE colour."""
        col = round(left + s_mm / 50.0 * (640 - left - right))
        return int(np.count_nonzero(np.all(img[:, col - 1:col + 2] == SITE, axis=-1).any(1)))

    for s_mm in (10.0, 40.0):
        assert rows_in_site_colour(s_mm) > 40, s_mm  # a dashed line down the chart
    # nothing at a lesion end that is not a reference site: only the reference line
    # (2 px, anti-aliased) crossing it
    assert rows_in_site_colour(20.0) < 8


def test_the_area_chart_is_drawn_below_when_the_profile_has_areas() -> None:
    rec = _rec(smooth=True)
    assert not np.any(np.all(profile_plot(rec) == AREA, axis=-1))
    rec.profile.area_smooth_mm2 = np.pi * rec.profile.diameter_mm ** 2 / 4
    img = profile_plot(rec, width=440, height=440)
    rows = np.flatnonzero(np.any(np.all(img == AREA, axis=-1), axis=1))
    assert rows.size and rows.min() > 0.6 * 440  # in the lower third


def test_band_titles_side_by_side_go_on_rows_of_their_own() -> None:
    """Issue 46: the titles of two shaded stretches a few mm apart printed over each other
    ("A overlapped" on "branch"); the second goes a row lower."""
    rec = _rec(smooth=True)
    stretches = {"a": [(10.0, 14.0)], "b": [(11.0, 15.0)]}
    rec.centerline_3d = SimpleNamespace(overlap_stretches_mm=lambda view: stretches[view])
    img = profile_plot(rec)
    left, right, top = 56, 14, 26
    x = round(left + 11.0 / 50.0 * (640 - left - right)) + 2

    def dark_rows(y0: int, y1: int) -> int:  # title ink (grey 90) in a row band
        ink = np.all(img[y0:y1, x:x + 60] <= 120, axis=-1)
        return int(np.count_nonzero(ink))

    assert dark_rows(top + 3, top + 14) > 20  # "A overlapped" on the first row
    assert dark_rows(top + 15, top + 26) > 20  # "B overlapped" on the second


def test_a_borderline_narrowing_is_shaded_and_titled() -> None:
    """Issue 46: a narrowing below the lesion floor whose interval reaches it is shown on
    the chart (a band over its extent, titled with its %DS), not only in the summary."""
    from viewer_app.plot import BORDERLINE_BAND

    rec = _rec(smooth=True)
    plain = profile_plot(rec)
    assert not np.any(np.all(plain == BORDERLINE_BAND, axis=-1))
    narrowing = SimpleNamespace(start_s_mm=38.0, end_s_mm=44.0, diameter_stenosis_pct=22.4)
    rec.lesions = SimpleNamespace(borderline=(SimpleNamespace(narrowing=narrowing),))
    img = profile_plot(rec)
    left, right = 56, 14
    band = np.flatnonzero(np.any(np.all(img == BORDERLINE_BAND, axis=-1), axis=0))
    assert band.size
    assert abs(band.min() - (left + 38.0 / 50.0 * (640 - left - right))) <= 1.5
    assert abs(band.max() - (left + 44.0 / 50.0 * (640 - left - right))) <= 1.5
