"""The phantom's tree, radii, stenosis and ground truth (recon/synth/tree.py)."""

import numpy as np
import pytest
from scipy.integrate import simpson

from recon.synth import PRESETS, make_phantom
from recon.synth.tree import TREE_EXTENT_MM


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_tree_is_heart_sized_and_inside_the_field(preset):
    for seed in range(4):
        case = make_phantom(preset, seed, render=False)
        t = case.truth
        main_X, main_r = t.vessels[0]
        main_len = np.sum(np.linalg.norm(np.diff(main_X, axis=0), axis=1))
        assert 79.0 < main_len < 141.0
        assert 2 <= len(t.vessels) <= 4
        assert main_r[0] > 1.7 and main_r[-1] < 1.2
        X = np.vstack([v[0] for v in t.vessels])
        assert np.abs(X).max() <= TREE_EXTENT_MM
        for view in (case.view_a, case.view_b_true):
            p = view.project(X)
            assert p.min() >= 20.0 and p.max() <= 490.0
        # Samples every 0.1 mm along the segment.
        steps = np.linalg.norm(np.diff(t.segment_X_world, axis=0), axis=1)
        assert np.allclose(steps, 0.1, atol=2e-3)
        assert 0.0 < t.stenosis_s_mm < t.segment_length_mm


def test_branches_leave_at_30_to_70_degrees():
    for seed in range(5):
        t = make_phantom("data1", seed, render=False).truth
        main_X = t.vessels[0][0]
        for Xb, _ in t.vessels[1:]:
            i = np.argmin(np.linalg.norm(main_X - Xb[0], axis=1))
            tm = main_X[min(i + 5, len(main_X) - 1)] - main_X[max(i - 5, 0)]
            tb = Xb[10] - Xb[0]
            cos = tm @ tb / np.linalg.norm(tm) / np.linalg.norm(tb)
            assert 28.0 < np.degrees(np.arccos(cos)) < 72.0


@pytest.mark.parametrize("pct", [10.0, 25.0, 50.0, 75.0])
def test_stenosis_minimum_radius(pct):
    t = make_phantom("data2", 1, stenosis_pct=pct, render=False).truth
    ref_r = t.reference_diameter_mm / 2.0
    lesion = np.abs(t.segment_s_mm - t.stenosis_s_mm) <= t.stenosis_length_mm / 2
    r_lesion = t.segment_radius_mm[lesion]
    assert r_lesion.min() == pytest.approx((1 - pct / 100) * ref_r, rel=0.02)
    assert t.mld_mm == pytest.approx(2 * r_lesion.min())
    assert 6.0 <= t.stenosis_length_mm <= 12.0
    # The narrowest point of the lesion is its centre (within a sample or two).
    i = np.argmin(r_lesion)
    assert abs(t.segment_s_mm[lesion][i] - t.stenosis_s_mm) < 0.5
    # Outside the lesion the lumen is the smooth undiseased taper.
    healthy = make_phantom("data2", 1, stenosis_pct=0.0, render=False).truth
    assert np.allclose(t.segment_radius_mm[~lesion], healthy.segment_radius_mm[~lesion])
    assert np.all(t.segment_radius_mm <= healthy.segment_radius_mm + 1e-12)


def test_segment_volume_against_an_independent_integral():
    t0 = make_phantom("data1", 2, stenosis_pct=0.0, render=False).truth
    f = 0.6
    t = make_phantom("data1", 2, stenosis_pct=100 * f, render=False).truth
    for tr in (t0, t):
        v = np.pi * simpson(tr.segment_radius_mm**2, x=tr.segment_s_mm)
        assert tr.segment_volume_mm3 == pytest.approx(v, rel=1e-4)
    # A cosine stenosis r_ref (1 - f g) removes pi r^2 Ls (f - 3 f^2 / 8) of lumen.
    r_c = t.reference_diameter_mm / 2
    removed = np.pi * r_c**2 * t.stenosis_length_mm * (f - 3 * f**2 / 8)
    assert t0.segment_volume_mm3 - t.segment_volume_mm3 == pytest.approx(removed, rel=0.02)


def test_projected_radius_helper():
    case = make_phantom("data1", 0, render=False)
    t = case.truth
    r_px = t.segment_radius_px(case.view_a)
    X = t.segment_X_world[0]
    expected = t.segment_radius_mm[0] * 1200.0 / case.view_a.depth_mm(X)[0] / 0.390625
    assert r_px[0] == pytest.approx(expected)
