"""View B's header error and the clinician's clicks (recon/synth/clicks.py)."""

import numpy as np

from recon.geometry import rotvec_from_rotation
from recon.synth import PRESETS, make_phantom
from recon.synth.clicks import WAYPOINT_MIN_GAP_PX, random_header_error


def test_random_header_error_magnitudes():
    rng = np.random.default_rng(0)
    view = PRESETS["data1"].view_b
    angles, shifts = [], []
    for _ in range(200):
        rotvec, t_mm = random_header_error(rng, view)
        angles.append(np.degrees(np.linalg.norm(rotvec)))
        shifts.append(np.linalg.norm(t_mm))
    # Two orthogonal rotations (about z and about u) of 1..2 degrees each.
    assert np.sqrt(2.0) - 0.01 < min(angles) and max(angles) < 2 * np.sqrt(2.0) + 0.01
    assert 3.0 < np.median(shifts) < 15.0


def test_header_error_is_the_documented_correction():
    case = make_phantom("data3", 5, render=False)
    t = case.truth
    again = case.view_b_nominal.with_correction(t.correction_rotvec, t.correction_t_mm)
    assert np.allclose(again.P, case.view_b_true.P)
    assert case.view_b_nominal == PRESETS["data3"].view_b
    assert case.view_a == PRESETS["data3"].view_a
    off = make_phantom("data3", 5, render=False, header_error=False)
    assert off.view_b_true == off.view_b_nominal
    # The correction carries the nominal rig onto the true one.
    R = case.view_b_true.R_view_from_world.T @ case.view_b_nominal.R_view_from_world
    angle = np.linalg.norm(rotvec_from_rotation(R.T))
    assert np.isclose(angle, np.linalg.norm(t.correction_rotvec))


def test_seeds_agree_with_the_projected_truth():
    for seed in range(5):
        case = make_phantom("data1", seed, render=False)
        t = case.truth
        seg = case.seeds.segments[0]
        assert seg.name == "main"
        for view, clicks in ((case.view_a, seg.a), (case.view_b_true, seg.b)):
            truth_px = t.segment_px(view)
            assert np.linalg.norm(clicks[0] - truth_px[0]) < 3.0
            assert np.linalg.norm(clicks[-1] - truth_px[-1]) < 3.0
            assert 3 <= len(clicks) <= 4  # ends plus 1-2 waypoints
            # Waypoints lie on the projected segment.
            d = np.linalg.norm(clicks[1:-1, None, :] - truth_px[None], axis=2).min(axis=1)
            assert np.all(d < 3.0)
        pa, pb, names = case.seeds.correspondences()
        assert names == list(t.feature_names)
        assert np.all(np.linalg.norm(pa - case.view_a.project(t.features_world), axis=1) < 3.0)
        assert np.all(np.linalg.norm(pb - case.view_b_true.project(t.features_world), axis=1) < 3.0)
        assert np.allclose(pa * 10, np.round(pa * 10))  # rounded to 0.1 px


def test_seeds_are_made_with_the_true_not_the_nominal_geometry():
    # With header error, the nominal projection of B is off by many pixels.
    errs_true, errs_nominal = [], []
    for seed in range(6):
        case = make_phantom("data2", seed, render=False)
        _, pb, _ = case.seeds.correspondences()
        X = case.truth.features_world
        errs_true.append(np.linalg.norm(pb - case.view_b_true.project(X), axis=1).mean())
        errs_nominal.append(np.linalg.norm(pb - case.view_b_nominal.project(X), axis=1).mean())
    assert max(errs_true) < 2.0
    assert np.mean(errs_nominal) > 3.0 * np.mean(errs_true)


def test_no_waypoint_crowds_another_click() -> None:
    """data1/128 foreshortens the distal quarter in view B onto its end: no waypoint there."""
    for preset, seed in (("data1", 128), ("static", 7), ("data3", 110)):
        seg = make_phantom(preset, seed, render=False).seeds.segments[0]
        for clicks in (seg.a, seg.b):
            gaps = np.linalg.norm(np.diff(np.asarray(clicks), axis=0), axis=1)
            assert len(clicks) >= 2 and gaps.min() >= WAYPOINT_MIN_GAP_PX, (preset, seed)
