"""The 95 % intervals of the measurements (recon.pose.uncertainty.measurement_intervals)."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d
from test_calibration import VIEW_A, VIEW_B
from test_uncertainty import clicks, prior_pose

from recon.correspond.triangulation import radius_mm_eq11
from recon.lumen.measure import lumen_profile, measure_lumen
from recon.lumen.surface import elliptic_cross_sections
from recon.pose.calibration import calibrate_supported
from recon.pose.uncertainty import measurement_intervals, radius_error_model
from recon.types import Centerline3D, arclength

SPACING_MM = 0.25


def tube(length_mm: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """A gently curved centerline (M, 3) through the isocenter and its true radius (M,):
    1.5 mm with a 50 % stenosis (cosine, 10 mm long) in the middle."""
    t = np.linspace(-0.5, 0.5, 4000)
    X = np.column_stack([length_mm * t, 8.0 * np.sin(3.0 * t), 20.0 * t**2])
    s = arclength(X)
    keep = np.searchsorted(s, np.arange(0.0, s[-1], SPACING_MM))
    X, s = X[keep], s[keep] - s[keep][0]
    mid = 0.5 * s[-1]
    bump = np.where(np.abs(s - mid) < 5.0, 0.5 * (1 + np.cos(np.pi * (s - mid) / 5.0)), 0.0)
    return X, 1.5 * (1.0 - 0.5 * bump)


def correlated(rng: np.random.Generator, m: int, sd: float, corr_mm: float) -> np.ndarray:
    f = gaussian_filter1d(rng.standard_normal(m), corr_mm / SPACING_MM / np.sqrt(2))
    return sd * f / np.std(f)


def centerline_of(X: np.ndarray, r_a: np.ndarray, r_b: np.ndarray) -> Centerline3D:
    T = np.gradient(X, axis=0)
    T /= np.linalg.norm(T, axis=1, keepdims=True)
    return Centerline3D(X_world=X, s_mm=arclength(X), tangents=T, radius_a_mm=r_a,
                        radius_b_mm=r_b, X_raw_world=X, points_a_px=np.zeros((len(X), 2)),
                        points_b_px=np.zeros((len(X), 2)))


def simulated(rng: np.random.Generator, rel_sd: float = 0.04):
    """One reconstruction as the pipeline would make it: B's true pose drawn from the
    prior, 6 clicks of 0.7 px noise, the supported calibration; the tube triangulated from
    its true projections under the calibrated pose; each view's radius in px off by a
    correlated relative error (sd ``rel_sd``, 1 mm), scaled back by eq. (11)."""
    truth_b = VIEW_B.with_correction(*prior_pose(rng.standard_normal(6)))
    pa, pb = clicks(truth_b, 6, 0.7, rng)
    cal = calibrate_supported(VIEW_A, VIEW_B, pa, pb)
    X, r = tube()
    from recon.geometry import triangulate

    ones = np.ones(len(X))
    Xe = triangulate(VIEW_A.project(X), truth_b.project(X), VIEW_A, cal.view_b)
    m = len(X)
    r_a = r * radius_mm_eq11(ones, Xe, VIEW_A) / radius_mm_eq11(ones, X, VIEW_A)
    r_b = r * radius_mm_eq11(ones, Xe, cal.view_b) / radius_mm_eq11(ones, X, truth_b)
    r_a = r_a * np.exp(correlated(rng, m, rel_sd, 1.0))
    r_b = r_b * np.exp(correlated(rng, m, rel_sd, 1.0))
    cl = centerline_of(Xe, r_a, r_b)
    area = elliptic_cross_sections(cl, VIEW_A, cal.view_b).area_mm2
    meas = measure_lumen(lumen_profile(cl.s_mm, area))
    true = {"mld_mm": 1.5, "segment_length_mm": float(arclength(X)[-1]),
            "diameter_stenosis_pct": 50.0}
    return cal, cl, meas, true


def test_every_measurement_has_an_interval_around_it():
    rng = np.random.default_rng(1)
    cal, cl, meas, _ = simulated(rng)
    iv = measurement_intervals(VIEW_A, VIEW_B, cal.posterior, cl, meas)
    numbers = {k for k, v in meas.to_dict().items() if not isinstance(v, bool)}
    assert set(iv.ci95) == numbers
    for key, (lo, hi) in iv.ci95.items():
        value = meas.to_dict()[key]
        assert lo <= value <= hi, key
    assert iv.ci95["mld_mm"][1] > iv.ci95["mld_mm"][0]
    assert iv.radius_lo_mm.shape == iv.radius_hi_mm.shape == cl.s_mm.shape
    assert np.all(iv.radius_lo_mm <= iv.radius_hi_mm)


def test_measured_from_an_arc_length_on_the_draws_skip_what_lies_before_it():
    """A branch's QCA from its carina on: with the stenosis (middle of the tube) before
    the measured stretch, the draws' MLD is the healthy part's, and its interval holds
    the same partial measurement's value, not the whole tube's MLD."""
    rng = np.random.default_rng(3)
    cal, cl, meas, _ = simulated(rng)
    s_from = 0.5 * cl.s_mm[-1] + 8.0  # past the 10 mm stenosis centred mid-tube
    area = elliptic_cross_sections(cl, VIEW_A, cal.view_b).area_mm2
    keep = cl.s_mm >= s_from
    part = measure_lumen(lumen_profile(cl.s_mm[keep], area[keep]))
    assert part.mld_mm > meas.mld_mm + 0.5  # the narrowing is not in the part
    iv = measurement_intervals(VIEW_A, VIEW_B, cal.posterior, cl, part,
                               measure_from_s_mm=s_from)
    lo, hi = iv.ci95["mld_mm"]
    assert lo <= part.mld_mm <= hi and lo > meas.mld_mm + 0.3
    lo_len, hi_len = iv.ci95["segment_length_mm"]
    assert lo_len <= part.segment_length_mm <= hi_len < 0.6 * meas.segment_length_mm


def test_the_intervals_cover_the_truth_of_simulated_reconstructions():
    """Pose from the prior, clicks and 2D radius errors as the intervals model them: the
    95 % intervals hold the truth in at least 16 of 20 cases (binomial: 95 % coverage
    gives fewer in 1.6 % of runs) and are not uselessly wide (median error at least a
    fifth of the interval's sd)."""
    rng = np.random.default_rng(7)
    hits = {"mld_mm": 0, "segment_length_mm": 0, "diameter_stenosis_pct": 0}
    z = {k: [] for k in hits}
    n = 20
    for _ in range(n):
        cal, cl, meas, true = simulated(rng)
        iv = measurement_intervals(VIEW_A, VIEW_B, cal.posterior, cl, meas)
        for key in hits:
            lo, hi = iv.ci95[key]
            hits[key] += lo <= true[key] <= hi
            z[key].append(abs(meas.to_dict()[key] - true[key]) / ((hi - lo) / 2 / 1.96))
    print({k: (hits[k], round(float(np.median(z[k])), 2)) for k in hits})
    for key in hits:
        assert hits[key] >= 0.8 * n, (key, hits[key], np.median(z[key]))
        assert np.median(z[key]) > 0.2, (key, np.median(z[key]))


def test_the_radius_error_model_recovers_a_known_error():
    rng = np.random.default_rng(2)
    X, r = tube(120.0)
    m = len(X)
    ea, eb = correlated(rng, m, 0.05, 1.0), correlated(rng, m, 0.05, 1.0)
    model = radius_error_model(arclength(X), r * np.exp(ea), r * np.exp(eb))
    assert np.median(model.local_sd) == pytest.approx(0.05, rel=0.3)
    assert 0.4 < model.correlation_mm < 2.5
    assert model.offset_sd < 0.02
    same = radius_error_model(arclength(X), r, r)  # two views that agree: no 2D error
    assert same.offset_sd == 0.0 and np.all(same.local_sd == 0.0)


def test_a_flagged_stretch_carries_the_other_views_reading_into_the_interval():
    """View A sees no narrowing (another vessel over the lesion, missed by the fit): the
    reported MLD is near the reference. With the stretch flagged for view A (as the
    cross-view check flags it) the interval holds the truth (the other view's reading), and
    the figures away from the stretch (the reference diameter) keep their width."""
    rng = np.random.default_rng(11)
    cal, cl, _, true = simulated(rng, rel_sd=0.02)
    s = cl.s_mm
    mid = 0.5 * s[-1]
    near = np.abs(s - mid) < 6.0
    r_a = cl.radius_a_mm.copy()
    r_a[near] = np.median(cl.radius_a_mm[~near])  # view A misses the narrowing
    from dataclasses import replace

    bad = replace(cl, radius_a_mm=r_a)
    area = elliptic_cross_sections(bad, VIEW_A, cal.view_b).area_mm2
    meas = measure_lumen(lumen_profile(bad.s_mm, area))
    plain = measurement_intervals(VIEW_A, VIEW_B, cal.posterior, bad, meas)
    flagged = measurement_intervals(VIEW_A, VIEW_B, cal.posterior, bad, meas, flagged_a=near)
    assert meas.mld_mm > true["mld_mm"] + 0.5
    lo, hi = flagged.ci95["mld_mm"]
    assert lo <= true["mld_mm"] <= hi, (lo, hi)
    width = {k: np.ptp(iv.ci95["reference_diameter_mm"]) for k, iv in
             (("plain", plain), ("flagged", flagged))}
    assert width["flagged"] < 1.5 * width["plain"], width
    assert flagged.flagged_mm[0] and not flagged.flagged_mm[1]
    assert flagged.flagged_mm[0][0][0] == pytest.approx(mid - 6.0, abs=0.5)


def test_a_flagged_detour_widens_the_length_interval_towards_the_chord():
    """A stretch of the 3D centerline that detoured (flagged): the segment-length interval
    reaches down to the length with the detour replaced by its chord."""
    rng = np.random.default_rng(12)
    cal, cl, meas, _ = simulated(rng, rel_sd=0.02)
    s = cl.s_mm
    X = cl.X_world.copy()
    mid = 0.5 * s[-1]
    near = np.abs(s - mid - 15.0) < 4.0
    bump = np.where(near, np.cos(np.pi * (s - mid - 15.0) / 8.0), 0.0)
    X[:, 2] += 6.0 * bump  # a 6 mm detour over 8 mm
    T = np.gradient(X, axis=0)
    T /= np.linalg.norm(T, axis=1, keepdims=True)
    from dataclasses import replace

    bent = replace(cl, X_world=X, s_mm=arclength(X), tangents=T)
    area = elliptic_cross_sections(bent, VIEW_A, cal.view_b).area_mm2
    meas = measure_lumen(lumen_profile(bent.s_mm, area))
    straight_length = float(arclength(cl.X_world)[-1])
    assert meas.segment_length_mm > straight_length + 3.0
    plain = measurement_intervals(VIEW_A, VIEW_B, cal.posterior, bent, meas)
    flagged = measurement_intervals(VIEW_A, VIEW_B, cal.posterior, bent, meas, flagged_b=near)
    assert plain.ci95["segment_length_mm"][0] > straight_length
    assert flagged.ci95["segment_length_mm"][0] <= straight_length + 0.5


def test_two_views_that_agree_still_leave_their_shared_fit_error():
    """Both views read the same radius everywhere (no disagreement to learn from): the MLD
    interval still spans the error both fits may share, COMMON_RADIUS_SD_PX of the
    lesion's radius in px (one sd of the MLD at least 0.7 of that, relative)."""
    from dataclasses import replace

    from recon.pose.uncertainty import COMMON_RADIUS_SD_PX

    rng = np.random.default_rng(13)
    cal, cl, _, _ = simulated(rng, rel_sd=0.0)
    same = replace(cl, radius_b_mm=cl.radius_a_mm.copy())
    area = elliptic_cross_sections(same, VIEW_A, cal.view_b).area_mm2
    meas = measure_lumen(lumen_profile(same.s_mm, area))
    iv = measurement_intervals(VIEW_A, VIEW_B, cal.posterior, same, meas)
    k = int(np.argmin(same.radius_a_mm))
    r_px = same.radius_a_mm[k] / radius_mm_eq11(np.ones(1), same.X_world[k : k + 1], VIEW_A)[0]
    lo, hi = iv.ci95["mld_mm"]
    sd_rel = (hi - lo) / 2 / 1.96 / meas.mld_mm
    assert sd_rel > 0.7 * COMMON_RADIUS_SD_PX / r_px, (sd_rel, r_px)
    assert iv.radius_error["common_sd_px"] == COMMON_RADIUS_SD_PX


def test_a_radius_that_stood_in_for_the_other_views_keeps_their_disagreement():
    """Where one view's fit was not trusted and the other view's radius stood in for it
    (recon.correspond.triangulation, step 5), the two radii agree by construction; the intervals
    take the error model from the views' own fits there, so the MLD interval is as wide
    as the disagreement they showed, not narrowed by the substitution."""
    from dataclasses import replace

    rng = np.random.default_rng(5)
    cal, cl, _, _ = simulated(rng)
    s = cl.s_mm
    stretch = np.abs(s - 0.5 * s[-1]) < 4.0  # the lesion, where view A's fit collapsed
    fit_a = np.where(stretch, 0.5 * cl.radius_a_mm, cl.radius_a_mm)
    stood_in = replace(cl, radius_a_mm=np.where(stretch, cl.radius_b_mm, cl.radius_a_mm),
                       overlap_a=stretch)
    area = elliptic_cross_sections(stood_in, VIEW_A, cal.view_b).area_mm2
    meas = measure_lumen(lumen_profile(s, area))
    widths = {}
    for name, c in (("hidden", stood_in),
                    ("kept", replace(stood_in, fit_radius_a_mm=fit_a,
                                     fit_radius_b_mm=cl.radius_b_mm))):
        lo, hi = measurement_intervals(VIEW_A, VIEW_B, cal.posterior, c, meas).ci95["mld_mm"]
        widths[name] = hi - lo
    assert widths["kept"] > 1.5 * widths["hidden"], widths
