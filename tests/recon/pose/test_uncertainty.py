"""The pose posterior (recon.pose.uncertainty) and the decision calibrate_supported makes."""

import numpy as np
import pytest
from test_calibration import VIEW_A, VIEW_B, heart_points

from recon.pose.calibration import CalibrationPriors, calibrate_supported
from recon.pose.calibration_model import ResidualModel
from recon.pose.uncertainty import click_sigma_px, named_axes, observability

PRIORS = CalibrationPriors()


def prior_pose(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rig correction (rotvec rad, t mm) of prior-sigma units z (6,), as the model maps it."""
    T = VIEW_B.R_view_from_world.T * np.asarray(PRIORS.translation_sigma_mm)[None, :]
    return np.deg2rad(PRIORS.rotation_sigma_deg) * z[:3], T @ z[3:]


def clicks(truth, k: int, noise_px: float, rng: np.random.Generator):
    X = rng.uniform(-35.0, 35.0, size=(k, 3))
    return (VIEW_A.project(X) + rng.normal(0, noise_px, (k, 2)),
            truth.project(X) + rng.normal(0, noise_px, (k, 2)))


def test_the_posterior_covers_poses_drawn_from_the_prior():
    """Truth drawn from the prior, clicks with 0.7 px noise: the squared Mahalanobis
    distance of the estimate under the Laplace covariance averages about 6 (chi^2, 6 dof).
    Under the unit-noise covariance the solver assumes (sigma 1 px) it would be ~3."""
    rng = np.random.default_rng(3)
    m2, sigmas = [], []
    for _ in range(60):
        z_true = rng.standard_normal(6)
        truth = VIEW_B.with_correction(*prior_pose(z_true))
        pa, pb = clicks(truth, 6, 0.7, rng)
        res = calibrate_supported(VIEW_A, VIEW_B, pa, pb, candidates=("full",))
        d = res.posterior.z_hat - z_true
        m2.append(float(d @ np.linalg.solve(res.posterior.cov_z, d)))
        sigmas.append(res.posterior.click_sigma_px)
    assert 4.5 < np.mean(m2) < 8.0, np.mean(m2)
    assert 0.5 < np.median(sigmas) < 1.0, np.median(sigmas)  # 0.7 px, pulled towards 1 px


def test_click_noise_is_estimated_from_many_residuals():
    rng = np.random.default_rng(0)
    truth = VIEW_B.with_correction(*prior_pose(rng.standard_normal(6)))
    for noise in (0.3, 0.7, 2.0):
        pa, pb = clicks(truth, 60, noise, rng)
        res = calibrate_supported(VIEW_A, VIEW_B, pa, pb, candidates=("full",))
        assert res.posterior.click_sigma_px == pytest.approx(noise, rel=0.25)


def test_click_sigma_falls_back_on_its_prior_without_residual_dof():
    J = np.eye(8)[:, :6]  # 6 parameters, 2 features' worth of residuals
    sigma, dof = click_sigma_px(np.zeros(8), J * 100.0, n_features=2, has_priors=True)
    assert dof == 0.0
    assert sigma == pytest.approx(1.0)


def test_the_baseline_translation_is_unobservable_and_left_to_the_header():
    rng = np.random.default_rng(5)
    truth = VIEW_B.with_correction(*prior_pose(rng.standard_normal(6)))
    pa, pb = clicks(truth, 40, 0.7, rng)
    res = calibrate_supported(VIEW_A, VIEW_B, pa, pb, candidates=("full",))
    model = ResidualModel(VIEW_A, VIEW_B, pa, pb, np.ones(40), PRIORS, False)
    _, J = model.residuals_and_jacobian(res.posterior.z_hat)
    e1 = named_axes(VIEW_A, res.view_b)[0]  # the calibrated baseline
    dz = np.concatenate([np.zeros(3), np.linalg.solve(model.T, e1)])  # 1 mm along the baseline
    assert np.max(np.abs(J[: 4 * 40] @ dz)) < 1e-6  # not one pixel moves
    obs = observability(res.posterior)
    rows = obs["directions"]
    assert rows["translation_baseline"]["status"] in ("header", "partly")
    # 40 marks fix the directions across the baseline
    for key in ("rotation_baseline", "rotation_cross", "translation_normal"):
        assert rows[key]["status"] == "images", rows[key]
    assert "depth scale" in obs["summary"]


def test_few_marks_leave_the_rotation_about_the_beams_normal_weak():
    """With three marks the rotation of B about the normal to both beams is barely fixed
    (the issue's weak direction): its posterior sd stays near the prior's."""
    rng = np.random.default_rng(8)
    truth = VIEW_B.with_correction(*prior_pose(rng.standard_normal(6)))
    pa, pb = clicks(truth, 3, 0.7, rng)
    res = calibrate_supported(VIEW_A, VIEW_B, pa, pb, candidates=("full",))
    post, prior = res.posterior.named_sd()
    ratio = post / prior
    assert ratio[1] > 0.8
    assert ratio[1] == max(ratio[:3])  # the weakest rotation


@pytest.mark.parametrize(
    ("error", "expected"),
    [("none", {"header"}), ("shift", {"translation", "full"}), ("rotation", {"full"})],
)
def test_the_correction_goes_only_as_far_as_the_clicks_support(error, expected):
    """A right header stays; a rig shift of ~15 mm is corrected; a 3-degree rotation
    about B's u axis needs the full correction. Five of six noise draws must choose as
    expected. (About B's v axis, near the weak normal to both beams, 3 degrees move the
    eight marks by about 0.5 px and the header often stands: the marks cannot tell.)"""
    rng = np.random.default_rng(11)
    hits = 0
    for _ in range(6):
        if error == "none":
            truth = VIEW_B
        elif error == "shift":
            truth = VIEW_B.with_correction(np.zeros(3), VIEW_B.R_view_from_world.T @ [12, -9, 0])
        else:
            truth = VIEW_B.with_correction(VIEW_B.R_view_from_world[0] * np.deg2rad(3.0),
                                           np.zeros(3))
        pa, pb = clicks(truth, 8, 0.7, rng)
        res = calibrate_supported(VIEW_A, VIEW_B, pa, pb)
        assert set(res.decision["candidates"]) == {"header", "translation", "full"}
        hits += res.correction in expected
        if res.correction == "header":
            assert np.allclose(res.view_b.R_view_from_world, VIEW_B.R_view_from_world)
            assert np.allclose(res.view_b.source_world, VIEW_B.source_world)
    assert hits >= 5


def test_unknown_correction_is_refused():
    from recon.pose.calibration import CalibrationError

    pa = VIEW_A.project(heart_points(4))
    pb = VIEW_B.project(heart_points(4))
    with pytest.raises(CalibrationError, match="unknown correction"):
        calibrate_supported(VIEW_A, VIEW_B, pa, pb, candidates=("rotation",))


def test_the_clicked_ends_spread_the_segment_length_as_the_click_noise_says() -> None:
    """A straight 3D segment seen at 4 px per mm in view A and, foreshortened, at 2 px per
    mm in view B: each end moves by the mean of the two views' along-vessel click errors
    (sigma 1 px) times their mm per px, so the length's sd is
    sqrt(2) * sqrt(0.25^2 + 0.5^2) / 2 = 0.395 mm with both ends clicked, 0.280 mm with the
    distal one only."""
    from recon.pose.uncertainty import _end_draws

    s = np.linspace(0.0, 30.0, 301)
    X = np.column_stack([s, np.zeros_like(s), np.zeros_like(s)])
    pa, pb = X[:, :2] * 4.0, X[:, :2] * 2.0
    rng = np.random.default_rng(0)
    both = _end_draws(rng, X, s, (pa, pb), 1.0, 20000)
    distal = _end_draws(rng, X, s, (pa, pb), 1.0, 20000, both_ends=False)
    assert np.std(both) == pytest.approx(np.sqrt(2) * np.hypot(0.25, 0.5) / 2, rel=0.03)
    assert np.std(distal) == pytest.approx(np.hypot(0.25, 0.5) / 2, rel=0.03)
    assert abs(np.mean(both)) < 0.01
    assert np.all(_end_draws(rng, X, s, (pa, pb), 0.0, 10) == 0.0)
