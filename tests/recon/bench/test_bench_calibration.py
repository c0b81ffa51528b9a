"""The calibration benchmark's reference poses (recon/bench/calibration.py)."""

from __future__ import annotations

import numpy as np
import pytest

from recon.bench.calibration import extra_landmarks, pose_errors, reference_poses
from recon.pose.calibration import CalibrationPriors, backprojection_residuals_px
from recon.synth import make_phantom


@pytest.mark.parametrize("preset", ["data1", "data3"])
def test_reference_poses_explain_exact_projections(preset: str) -> None:
    """Both references differ from the truth only along the baseline: images are unchanged."""
    case = make_phantom(preset, 3, render=False)
    X = case.truth.segment_X_world[::50]
    pa, pb = case.view_a.project(X), case.view_b_true.project(X)
    header_err = backprojection_residuals_px(case.view_a, case.view_b_nominal, pa, pb)
    assert np.max(header_err) > 1.0  # the header is visibly wrong
    for view_b in reference_poses(case.view_a, case.view_b_nominal, case.view_b_true):
        residual = backprojection_residuals_px(case.view_a, view_b, pa, pb)
        assert np.max(residual) < 1e-3


def test_prior_gauge_minimises_the_prior_norm() -> None:
    case = make_phantom("data2", 5, render=False)
    priors = CalibrationPriors()
    at_header, from_prior = reference_poses(
        case.view_a, case.view_b_nominal, case.view_b_true, priors
    )
    axes = case.view_b_nominal.R_view_from_world
    sigma = np.asarray(priors.translation_sigma_mm)

    def prior_norm(t_mm: np.ndarray) -> float:
        return float(np.sum((axes @ t_mm / sigma) ** 2))

    n = case.view_b_true.source_world - case.view_a.source_world
    n /= np.linalg.norm(n)
    t = np.asarray(from_prior.t_corr_mm)
    assert abs(np.asarray(at_header.t_corr_mm) @ n) < 1e-9  # held at the header's value
    for step_mm in (-0.5, 0.5):
        assert prior_norm(t) < prior_norm(t + step_mm * n)


def test_pose_errors_vanish_for_the_true_pose() -> None:
    case = make_phantom("static", 1, render=False)
    errors = pose_errors(
        case.view_b_true, case.view_b_true, case.view_a, case.truth.segment_X_world
    )
    assert all(v < 1e-6 for v in errors.values())


def test_extra_landmarks_are_noisy_clicks_on_the_vessel_ends() -> None:
    case = make_phantom("data1", 2, render=False)
    rng = np.random.default_rng(0)
    n_branches = len(case.truth.vessels) - 1
    la, lb = extra_landmarks(case, rng, main_ends=False)
    assert la.shape == lb.shape == (n_branches, 2)
    ends = np.array([v[0][-1] for v in case.truth.vessels[1:]])
    assert np.max(np.abs(la - case.view_a.project(ends))) < 4.0  # 0.7 px sd clicks
    assert np.max(np.abs(lb - case.view_b_true.project(ends))) < 4.0
    assert not np.allclose(la, case.view_a.project(ends))  # noise is there
    la2, _ = extra_landmarks(case, rng, main_ends=True)
    assert la2.shape == (n_branches + 2, 2)
