import json

import numpy as np
import pytest

from recon.geometry import ViewGeometry
from recon.lumen.measure import LumenProfile, Measurements, lumen_profile, measure_lumen
from recon.lumen.surface import elliptic_cross_sections
from recon.types import Centerline3D


def cosine_profile(p=0.5, length_mm=10.0, s0=45.0, r0=2.0, r1=1.0, total=100.0, step=0.25):
    """The phantom's shape: linear taper times a raised-cosine narrowing."""
    s = np.arange(0.0, total + 1e-9, step)
    r_ref = r0 + (r1 - r0) * s / total
    x = (s - s0) / length_mm
    bump = np.where(np.abs(x) < 0.5, 0.5 * (1.0 + np.cos(2 * np.pi * x)), 0.0)
    return s, r_ref * (1.0 - p * bump), r_ref


@pytest.mark.parametrize(
    "p, length_mm, s0",
    [(0.5, 10.0, 45.0), (0.3, 6.0, 70.0), (0.7, 12.0, 30.0), (0.5, 8.0, 55.0)],
)
def test_cosine_stenosis_on_tapering_reference(p, length_mm, s0):
    s, r, r_ref = cosine_profile(p, length_mm, s0)
    m = measure_lumen(lumen_profile(s, np.pi * r**2))
    i = np.argmin(r)
    assert m.mld_mm == pytest.approx(2 * r[i], abs=0.02)
    assert m.mld_s_mm == pytest.approx(s[i], abs=0.5)
    assert m.reference_diameter_mm == pytest.approx(2 * r_ref[i], rel=0.01)
    assert m.diameter_stenosis_pct == pytest.approx(100 * p, abs=0.5)
    assert m.area_stenosis_pct == pytest.approx(100 * (1 - (1 - p) ** 2), abs=1.0)
    assert m.lesion_length_mm == pytest.approx(length_mm, abs=0.3)
    assert m.lesion_start_s_mm == pytest.approx(s0 - length_mm / 2, abs=0.3)
    assert m.lesion_end_s_mm == pytest.approx(s0 + length_mm / 2, abs=0.3)
    assert m.mla_mm2 == pytest.approx(np.pi * r[i] ** 2, rel=0.02)
    assert m.segment_length_mm == pytest.approx(100.0)
    assert m.has_lesion


def test_reference_line_follows_the_taper_outside_the_lesion():
    s, r, r_ref = cosine_profile()
    prof = lumen_profile(s, np.pi * r**2)
    assert isinstance(prof, LumenProfile)
    np.testing.assert_allclose(prof.reference_diameter_mm, 2 * r_ref, rtol=0.005)
    np.testing.assert_allclose(prof.diameter_mm, 2 * r, rtol=1e-12)
    assert prof.relative_deficit.max() == pytest.approx(0.5, abs=0.01)


def test_noisy_profile_stays_within_targets():
    rng = np.random.default_rng(3)
    s, r, r_ref = cosine_profile(0.5, 10.0, 45.0)
    noisy = r * (1 + 0.02 * rng.standard_normal(r.size))
    m = measure_lumen(lumen_profile(s, np.pi * noisy**2))
    i = np.argmin(r)
    assert abs(m.mld_mm - 2 * r[i]) < 0.1
    assert abs(m.diameter_stenosis_pct - 50.0) < 3.0
    assert abs(m.lesion_length_mm - 10.0) < 1.0


def test_no_stenosis_gives_zero_and_a_clear_result():
    s, r, _ = cosine_profile(p=0.0)
    m = measure_lumen(lumen_profile(s, np.pi * r**2))
    assert isinstance(m, Measurements)
    assert abs(m.diameter_stenosis_pct) < 1.0
    assert abs(m.area_stenosis_pct) < 2.0
    assert m.lesion_length_mm == 0.0
    assert not m.has_lesion
    assert m.lesion_start_s_mm == m.lesion_end_s_mm == m.mld_s_mm
    d = m.to_dict()
    json.dumps(d)  # JSON-ready
    assert d["has_lesion"] is False and d["segment_length_mm"] == pytest.approx(100.0)


def test_mild_lesion_wins_over_a_narrower_distal_end():
    # 30 % at 3.4 mm reference -> 2.38 mm, larger than the 2.0 mm distal end.
    s, r, _ = cosine_profile(p=0.3, length_mm=8.0, s0=25.0)
    m = measure_lumen(lumen_profile(s, np.pi * r**2))
    assert m.mld_s_mm == pytest.approx(25.0, abs=0.5)
    assert m.diameter_stenosis_pct == pytest.approx(30.0, abs=0.5)


def test_profile_from_elliptic_sections_of_a_straight_vessel():
    s, r, _ = cosine_profile(0.5, 10.0, 45.0)
    X = np.column_stack([np.zeros_like(s), np.zeros_like(s), s - 50.0])
    tangents = np.tile([0.0, 0.0, 1.0], (len(s), 1))
    cl = Centerline3D(
        X_world=X,
        s_mm=s,
        tangents=tangents,
        radius_a_mm=r,
        radius_b_mm=r,
        X_raw_world=X,
        points_a_px=np.zeros((len(s), 2)),
        points_b_px=np.zeros((len(s), 2)),
    )
    va = ViewGeometry(-30.0, 0.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)
    vb = ViewGeometry(30.0, 0.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)
    sections = elliptic_cross_sections(cl, va, vb)
    m = measure_lumen(lumen_profile(cl.s_mm, sections.area_mm2))
    assert m.mld_mm == pytest.approx(2 * r.min(), abs=0.02)
    assert m.diameter_stenosis_pct == pytest.approx(50.0, abs=0.5)


@pytest.mark.parametrize(
    "s, area",
    [
        (np.arange(5.0), np.ones(4)),
        (np.arange(5.0), np.array([1.0, 1.0, 0.0, 1.0, 1.0])),
        (np.array([0.0, 1.0, 1.0, 2.0]), np.ones(4)),
        (np.arange(5.0), np.array([1.0, np.nan, 1.0, 1.0, 1.0])),
    ],
)
def test_bad_profiles_raise_value_error(s, area):
    with pytest.raises(ValueError):
        lumen_profile(s, area)


def test_a_fading_trace_end_is_not_taken_for_the_lesion():
    s, radius, _ = cosine_profile(p=0.4, length_mm=8.0, s0=45.0)
    faded = radius.copy()
    faded[s > s[-1] - 1.0] *= 0.5  # the last millimetre: where the trace fades out
    m = measure_lumen(lumen_profile(s, np.pi * faded**2))
    assert abs(m.mld_s_mm - 45.0) < 1.0
    assert m.lesion_end_s_mm < s[-1] - 10.0


@pytest.mark.parametrize("n, window", [(5, 5), (9, 5), (40, 11), (41, 41), (400, 61), (401, 399)])
def test_savgol_cubic_equals_scipy_savgol_filter(n: int, window: int) -> None:
    from scipy.signal import savgol_filter

    from recon.lumen.measure import savgol_cubic

    rng = np.random.default_rng(n * 1000 + window)
    s = np.linspace(0.0, 3.0, n)
    values = 2.5 + np.sin(3.0 * s) + 0.4 * s**2 + 0.05 * rng.standard_normal(n)
    expected = savgol_filter(values, window, 3, mode="interp")
    assert np.allclose(savgol_cubic(values, window), expected, rtol=0.0, atol=1e-9)
    # a cubic passes through unchanged, edges included
    cubic = 1.0 - 2.0 * s + 0.5 * s**2 - 0.3 * s**3
    assert np.allclose(savgol_cubic(cubic, window), cubic, rtol=0.0, atol=1e-9)
