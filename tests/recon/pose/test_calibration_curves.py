"""Calibration on the whole traced curves, with the clicks (recon.pose.calibration_curves)."""

import numpy as np
import pytest
from test_calibration import VIEW_A, VIEW_B, rotation_error_deg
from test_uncertainty import prior_pose

from recon.bench.common import scale_free_error_mm
from recon.geometry import triangulate
from recon.pose.calibration import _initial_parameters, calibrate_supported
from recon.pose.calibration_curves import CurveResiduals, _subsample, calibrate_with_curves
from recon.pose.calibration_model import ResidualModel
from recon.pose.uncertainty import observability


def vessel(n: int = 600) -> np.ndarray:
    """A vessel (n, 3) winding round the heart: one and a half turns of a wide helix, so
    its projections turn against the epipolar lines more than once."""
    t = np.linspace(-2.4, 2.4, n)
    return np.column_stack([45.0 * np.cos(t), 45.0 * np.sin(t), 12.0 * t])


def curves_of(X: np.ndarray, view_b, rng: np.random.Generator, noise_px: float):
    return (VIEW_A.project(X) + rng.normal(0, noise_px, (len(X), 2)),
            view_b.project(X) + rng.normal(0, noise_px, (len(X), 2)))


def segment_error_mm(view_b, truth_b, X: np.ndarray) -> float:
    """Scale-free 3D RMS error (mm) of X (n, 3) triangulated with view B's estimate."""
    X_rec = triangulate(VIEW_A.project(X), truth_b.project(X), VIEW_A, view_b)
    return scale_free_error_mm(X_rec, X, VIEW_A.source_world)[0]


def residuals(truth_b, ca, cb) -> tuple[CurveResiduals, np.ndarray]:
    model = ResidualModel(VIEW_A, VIEW_B, ca[[0, -1]], cb[[0, -1]], np.ones(2), None, False)
    return (CurveResiduals(model, _subsample(ca, 6.0), _subsample(cb, 6.0), ca, cb),
            _initial_parameters(model, truth_b))


def test_the_epipolar_distances_vanish_at_the_true_pose_only():
    truth_b = VIEW_B.with_correction(*prior_pose(np.array([1.5, -1.0, 1.2, 1.0, -1.0, 0.5])))
    ca, cb = curves_of(vessel(), truth_b, np.random.default_rng(0), 0.0)
    res, z_true = residuals(truth_b, ca, cb)
    d_true = res.distances(z_true[None])[0]
    d_header = res.distances(np.zeros((1, res.model.n_params)))[0]
    assert np.max(np.abs(d_true)) < 0.2  # the polyline's chords at a tangency
    assert np.max(np.abs(d_header)) > 3.0  # the header's lines miss the other curve


def test_the_curve_jacobian_is_exact():
    truth_b = VIEW_B.with_correction(*prior_pose(np.array([1.5, -1.0, 1.2, 1.0, -1.0, 0.5])))
    ca, cb = curves_of(vessel(), truth_b, np.random.default_rng(0), 0.0)
    res, _ = residuals(truth_b, ca, cb)
    z = np.full(res.model.n_params, 0.1)
    d, J = res.distances_and_jacobian(z)
    assert np.count_nonzero(d) > 5
    h = 1e-6
    for k in range(res.model.n_params):
        e = np.zeros_like(z)
        e[k] = h
        fd = (res.distances((z + e)[None])[0] - res.distances((z - e)[None])[0]) / (2 * h)
        smooth = np.abs(fd) < 1e3  # away from a switch of the nearest vertex or a crossing
        assert np.allclose(J[smooth, k], fd[smooth], atol=1e-4, rtol=1e-4)


def test_the_curves_fix_what_two_clicked_ends_leave_to_the_priors():
    """Only the two ends clicked (0.5 px noise): the poses from the clicks plus the traced
    curves (0.3 px noise) are nearer the truth than the clicks alone, in rotation and in
    the vessel's 3D error without the baseline scale, over 12 rig errors drawn from the
    priors."""
    rng = np.random.default_rng(5)
    X = vessel()
    clicks_only, joint = [], []
    for _ in range(12):
        truth_b = VIEW_B.with_correction(*prior_pose(rng.standard_normal(6)))
        ca, cb = curves_of(X, truth_b, rng, 0.3)
        pa = VIEW_A.project(X[[0, -1]]) + rng.normal(0, 0.5, (2, 2))
        pb = truth_b.project(X[[0, -1]]) + rng.normal(0, 0.5, (2, 2))
        first = calibrate_supported(VIEW_A, VIEW_B, pa, pb, candidates=("full",))
        both = calibrate_with_curves(VIEW_A, VIEW_B, pa, pb, ca, cb, initial=first)
        assert both.correction == "curves"
        assert both.decision["curve_median_px"]["after"] <= 0.5
        clicks_only.append((rotation_error_deg(first.view_b, truth_b),
                            segment_error_mm(first.view_b, truth_b, X)))
        joint.append((rotation_error_deg(both.view_b, truth_b),
                      segment_error_mm(both.view_b, truth_b, X)))
    clicks_only, joint = np.array(clicks_only), np.array(joint)
    assert np.median(joint[:, 0]) < 0.7 * np.median(clicks_only[:, 0]), (joint, clicks_only)
    assert np.median(joint[:, 1]) < np.median(clicks_only[:, 1]), (joint, clicks_only)


def test_a_trace_that_runs_on_past_the_end_is_discounted():
    """View B's trace runs 60 px on along a neighbour, out of the epipolar lines view A's
    vessel covers: the Cauchy loss keeps the pose within a fraction of a degree of the one
    from the clean curves (a quadratic loss moves it by degrees)."""
    rng = np.random.default_rng(2)
    X = vessel()
    truth_b = VIEW_B.with_correction(*prior_pose(rng.standard_normal(6)))
    ca, cb = curves_of(X, truth_b, rng, 0.3)
    pa = VIEW_A.project(X[[0, 300, -1]]) + rng.normal(0, 0.5, (3, 2))
    pb = truth_b.project(X[[0, 300, -1]]) + rng.normal(0, 0.5, (3, 2))
    # the tail crosses the epipolar pencil outward, beyond the lines the vessel covers
    epipole = truth_b.project(VIEW_A.source_world[None])[0]
    angle = np.unwrap(np.arctan2(*(cb - epipole).T[::-1]))
    radial = (cb[-1] - epipole) / np.linalg.norm(cb[-1] - epipole)
    across = np.array([-radial[1], radial[0]])
    if abs(angle[-1] - angle.max()) > abs(angle[-1] - angle.min()):
        across = -across
    tail = cb[-1] + np.outer(np.arange(1, 61), across)
    tail_angle = np.arctan2(*(tail[-1] - epipole)[::-1])
    assert not angle.min() <= np.unwrap([angle[-1], tail_angle])[1] <= angle.max()
    clean = calibrate_with_curves(VIEW_A, VIEW_B, pa, pb, ca, cb)
    run_on = calibrate_with_curves(VIEW_A, VIEW_B, pa, pb, ca, np.vstack([cb, tail]))
    assert rotation_error_deg(run_on.view_b, clean.view_b) < 0.3
    assert run_on.decision["curve_outlier_fraction"] > 0.01
    plain = calibrate_with_curves(VIEW_A, VIEW_B, pa, pb, ca, np.vstack([cb, tail]),
                                  loss_scale=1e6)  # a quadratic loss: the tail pulls
    assert rotation_error_deg(plain.view_b, clean.view_b) > 1.0


def test_the_joint_posterior_is_narrower_and_says_so():
    rng = np.random.default_rng(4)
    X = vessel()
    truth_b = VIEW_B.with_correction(*prior_pose(rng.standard_normal(6)))
    ca, cb = curves_of(X, truth_b, rng, 0.3)
    pa = VIEW_A.project(X[[0, -1]]) + rng.normal(0, 0.5, (2, 2))
    pb = truth_b.project(X[[0, -1]]) + rng.normal(0, 0.5, (2, 2))
    first = calibrate_supported(VIEW_A, VIEW_B, pa, pb, candidates=("full",))
    both = calibrate_with_curves(VIEW_A, VIEW_B, pa, pb, ca, cb, initial=first)
    assert np.trace(both.posterior.cov_pose[:3, :3]) < np.trace(first.posterior.cov_pose[:3, :3])
    words = observability(both.posterior)
    assert words["summary"]
    assert both.error_after_px == pytest.approx(
        float(np.mean(both.residuals_px)), rel=1e-9)


def test_the_pipeline_calibrates_on_the_curves_when_asked():
    from recon.bench.common import case_angiograms
    from recon.pipeline import ReconstructionOptions, reconstruct_pair
    from recon.synth import make_phantom

    case = make_phantom("data1", 4)
    a, b = case_angiograms(case)
    rec = reconstruct_pair(a, b, case.seeds, ReconstructionOptions(calibration="curves",
                                                                   voxel_mm=0.6))
    report = rec.report()["calibration"]
    assert report["correction"] == "curves"
    assert report["decision"]["clicks_only"]["chosen"] == "full"
    assert report["decision"]["curve_points"] > 10
    assert report["observability"]["summary"]
    assert rec.intervals is not None and rec.intervals.ci95["mld_mm"][0] < rec.measurements.mld_mm
