import numpy as np
import pytest

from recon.geometry import ViewGeometry, rotvec_from_rotation
from recon.pose.calibration import (
    CalibrationError,
    CalibrationPriors,
    backprojection_residuals_px,
    calibrate,
    refine_with_matches,
)
from recon.pose.calibration_model import ResidualModel

# Data 1 of the seed paper's Table 1.
VIEW_A = ViewGeometry(45.5, -28.2, 1200.0, 749.0, (0.39, 0.39), 512, 512)
VIEW_B = ViewGeometry(-24.8, -27.0, 1147.0, 844.0, (0.39, 0.39), 512, 512)


def header_error(seed: int = 0, along_baseline: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """A realistic rig error: ~1.5 deg rotation, ~10 mm SOD, a few mm of shift."""
    rng = np.random.default_rng(seed)
    rotvec = np.deg2rad(rng.uniform(1.0, 2.0, 3) * rng.choice([-1, 1], 3)) / np.sqrt(2)
    t = VIEW_B.nominal_axes.T @ np.array([3.0, -4.0, 10.0]) * rng.choice([-1, 1], 3)
    if not along_baseline:  # remove the unobservable component (see the module docstring)
        n = VIEW_B.source_world - VIEW_A.source_world
        n /= np.linalg.norm(n)
        t -= (t @ n) * n
    return rotvec, t


def heart_points(k: int, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-35.0, 35.0, size=(k, 3))


def rotation_error_deg(view: ViewGeometry, truth: ViewGeometry) -> float:
    return float(np.degrees(np.linalg.norm(rotvec_from_rotation(view.R_corr @ truth.R_corr.T))))


def rig_error_mm(view: ViewGeometry, truth: ViewGeometry, X: np.ndarray) -> float:
    """Mean displacement of X under the rig error (true rig -> estimated rig)."""
    moved = (X - truth.t_corr_mm) @ (view.R_corr @ truth.R_corr.T).T + view.t_corr_mm
    return float(np.mean(np.linalg.norm(moved - X, axis=1)))


def make_case(k: int, seed: int = 0, noise_px: float = 0.0, along_baseline: bool = True):
    rotvec, t = header_error(seed, along_baseline)
    truth = VIEW_B.with_correction(rotvec, t)
    X = heart_points(k, seed + 1)
    rng = np.random.default_rng(seed + 2)
    pa = VIEW_A.project(X) + rng.normal(0, noise_px, (k, 2))
    pb = truth.project(X) + rng.normal(0, noise_px, (k, 2))
    return truth, X, pa, pb


def test_model_matches_geometry_triangulation():
    from recon.geometry import triangulate

    truth, X, pa, pb = make_case(7)
    model = ResidualModel(VIEW_A, truth, pa, pb, np.ones(7), CalibrationPriors(), False)
    proj_a, proj_b = model.project_pairs(np.zeros((1, 6)))
    X_tri = triangulate(pa, pb, VIEW_A, truth, method="paper")
    assert np.allclose(X_tri, X, atol=1e-6)
    assert np.allclose(proj_a[0], VIEW_A.project(X_tri), atol=1e-8)
    assert np.allclose(proj_b[0], truth.project(X_tri), atol=1e-8)
    biased = backprojection_residuals_px(VIEW_A, VIEW_B, pa, pb)
    assert biased.shape == (7, 2) and np.all(biased.mean(axis=0) > 1.0)


@pytest.mark.parametrize("intrinsics", [False, True])
@pytest.mark.parametrize("priors", [CalibrationPriors(), None])
def test_jacobian_matches_central_differences(priors, intrinsics):
    if priors is None and intrinsics:
        return
    truth, X, pa, pb = make_case(9, noise_px=0.5)
    model = ResidualModel(VIEW_A, VIEW_B, pa, pb, np.linspace(0.5, 2, 9), priors, intrinsics)
    z = np.random.default_rng(3).normal(0, 0.4, model.n_params)
    r, J = model.residuals_and_jacobian(z)
    assert np.allclose(r, model.residuals(z[None])[0], rtol=0, atol=1e-10)
    h = 1e-6
    steps = h * np.eye(model.n_params)
    J_fd = (model.residuals(z + steps) - model.residuals(z - steps)).T / (2 * h)
    scale = np.max(np.abs(J), axis=0)
    assert np.max(np.abs(J - J_fd) / scale) < 1e-6


def test_palm_recovers_the_true_pose_without_noise():
    truth, X, pa, pb = make_case(8, along_baseline=False)
    result = calibrate(VIEW_A, VIEW_B, pa, pb, priors=None)
    assert result.converged and result.method == "palm"
    assert result.error_before_px > 1.0
    assert result.error_after_px < 1e-6
    assert rotation_error_deg(result.view_b, truth) < 0.01
    assert np.linalg.norm(np.subtract(result.view_b.t_corr_mm, truth.t_corr_mm)) < 0.05
    assert result.error_after_mm == pytest.approx(result.error_after_px * 0.39, rel=1e-6)
    assert result.view_a is VIEW_A and result.n_features == 8 and result.warnings == ()


def test_baseline_translation_is_unobservable():
    # A translation of B's rig along the baseline scales the scene about A's source: eq. (5)
    # cannot see it, which is why the priors (or the header, without priors) fix it.
    truth, X, pa, pb = make_case(8, along_baseline=False)
    n = truth.source_world - VIEW_A.source_world
    shifted = truth.with_correction(np.zeros(3), 0.05 * n)
    assert np.max(backprojection_residuals_px(VIEW_A, shifted, pa, pb)) < 1e-6


def test_palm_with_priors_fixes_rotation_and_improves_pose():
    truth, X, pa, pb = make_case(12)
    result = calibrate(VIEW_A, VIEW_B, pa, pb)
    assert result.error_after_px < 0.1 < result.error_before_px
    assert rotation_error_deg(result.view_b, truth) < 0.25 * rotation_error_deg(VIEW_B, truth)
    assert rig_error_mm(result.view_b, truth, X) < rig_error_mm(VIEW_B, truth, X)


@pytest.mark.parametrize("seed", range(6))
def test_palm_always_reduces_the_error_with_noise(seed):
    truth, X, pa, pb = make_case(6, seed=seed, noise_px=1.0)
    result = calibrate(VIEW_A, VIEW_B, pa, pb)
    assert result.converged
    assert result.error_after_px < result.error_before_px
    assert result.error_after_px < 1.0


@pytest.mark.parametrize("k", [2, 3])
def test_few_features_fit_exactly_and_priors_keep_the_pose_plausible(k):
    for seed in range(4):
        truth, X, pa, pb = make_case(k, seed=seed)
        result = calibrate(VIEW_A, VIEW_B, pa, pb)
        assert result.error_after_px < 0.05 * result.error_before_px
        assert result.error_after_px < 0.5  # the priors hold back a little
        assert any("underdetermined" in w for w in result.warnings)
        # a sliver of rotation may trade for translation; the rig as a whole gets closer
        assert rotation_error_deg(result.view_b, truth) < 1.1 * rotation_error_deg(VIEW_B, truth)
        assert rig_error_mm(result.view_b, truth, X) < rig_error_mm(VIEW_B, truth, X)


def test_palm_lm_and_anneal_agree():
    truth, X, pa, pb = make_case(8, noise_px=0.5)
    results = {m: calibrate(VIEW_A, VIEW_B, pa, pb, method=m) for m in ("palm", "lm", "anneal")}
    palm = results["palm"]
    for name in ("lm", "anneal"):
        other = results[name]
        assert other.method == name
        assert other.error_after_px == pytest.approx(palm.error_after_px, rel=1e-3, abs=1e-4)
        assert rotation_error_deg(other.view_b, palm.view_b) < 0.01
        assert np.allclose(other.view_b.t_corr_mm, palm.view_b.t_corr_mm, atol=0.05)


def test_huber_resists_mismatched_pairs():
    truth, X, pa, pb = make_case(200, along_baseline=False, noise_px=0.3)
    pb_bad = pb.copy()
    pb_bad[:10] += np.random.default_rng(5).normal(0, 25, (10, 2))  # 5 % mismatches
    pb_bad = np.clip(pb_bad, 0, 511)
    clean = calibrate(VIEW_A, VIEW_B, pa[10:], pb[10:], priors=None)
    plain = calibrate(VIEW_A, VIEW_B, pa, pb_bad, priors=None)
    robust = calibrate(VIEW_A, VIEW_B, pa, pb_bad, priors=None, loss="huber", loss_scale_px=1.0)
    assert rotation_error_deg(plain.view_b, clean.view_b) > 0.2
    assert rotation_error_deg(robust.view_b, clean.view_b) < 0.2 * rotation_error_deg(
        plain.view_b, clean.view_b
    )
    assert np.median(robust.residuals_px[10:]) < 0.3
    assert any("check the click" in w for w in robust.warnings)


def test_refine_with_matches_equals_calibrating_all_points():
    truth, X, pa, pb = make_case(150, noise_px=0.3, along_baseline=False)
    first = calibrate(VIEW_A, VIEW_B, pa[:3], pb[:3])
    refined = refine_with_matches(VIEW_A, VIEW_B, pa[:3], pb[:3], pa[3:], pb[3:], initial=first)
    direct = calibrate(VIEW_A, VIEW_B, pa, pb, loss="huber")
    assert refined.n_features == 150 and refined.converged
    assert rotation_error_deg(refined.view_b, direct.view_b) < 1e-4
    assert refined.error_after_px < 0.4 and refined.error_before_px > 1.0
    assert rig_error_mm(refined.view_b, truth, X) < rig_error_mm(VIEW_B, truth, X)


def test_estimate_intrinsics_runs_and_fits():
    truth, X, pa, pb = make_case(20, noise_px=0.2)
    result = calibrate(VIEW_A, VIEW_B, pa, pb, estimate_intrinsics=True)
    assert result.converged and result.error_after_px < 0.3
    assert abs(result.view_b.sid_mm - VIEW_B.sid_mm) < 30
    assert result.view_a is not None and abs(result.view_a.sid_mm - VIEW_A.sid_mm) < 30


def test_ill_conditioned_views_warn():
    near_b = ViewGeometry(40.0, -25.0, 1147.0, 844.0, (0.39, 0.39), 512, 512)
    X = heart_points(8)
    result = calibrate(VIEW_A, near_b, VIEW_A.project(X), near_b.project(X))
    assert any(w.startswith("ill-conditioned") for w in result.warnings)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda pa, pb: (pa[:1], pb[:1]), "at least 2"),
        (lambda pa, pb: (pa, pb[:-1]), "counts differ"),
        (lambda pa, pb: (np.where(np.arange(6)[:, None] == 2, np.nan, pa), pb), "feature 3"),
        (lambda pa, pb: (pa, pb + [600.0, 0.0]), "outside view B"),
        (lambda pa, pb: (pa[:, :1], pb), "shape"),
    ],
)
def test_bad_inputs_raise(change, message):
    truth, X, pa, pb = make_case(6)
    bad_a, bad_b = change(pa, pb)
    with pytest.raises(CalibrationError, match=message):
        calibrate(VIEW_A, VIEW_B, bad_a, bad_b)


def test_bad_options_raise():
    truth, X, pa, pb = make_case(4)
    with pytest.raises(CalibrationError, match="at least 5"):
        calibrate(VIEW_A, VIEW_B, pa, pb, priors=None)
    with pytest.raises(CalibrationError, match="unknown calibration method"):
        calibrate(VIEW_A, VIEW_B, pa, pb, method="newton")
    with pytest.raises(CalibrationError, match="huber"):
        calibrate(VIEW_A, VIEW_B, pa, pb, method="lm", loss="huber")
    with pytest.raises(CalibrationError, match="weights"):
        calibrate(VIEW_A, VIEW_B, pa, pb, weights=np.ones(3))
    with pytest.raises(CalibrationError, match="positive"):
        CalibrationPriors(rotation_sigma_deg=0.0)
    assert issubclass(CalibrationError, ValueError)
