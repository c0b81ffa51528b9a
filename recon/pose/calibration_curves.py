"""Calibration on the whole traced curves, jointly with the clicks.

The clicks (:mod:`recon.pose.calibration`, eq. 5) fix view B's pose at a handful of
points. The two traced centerlines say more: with the right pose, the epipolar
line of every traced point of one view meets the other view's curve. Where it
misses, the distance from the line to the nearest point of that curve is the
evidence of a pose error (the paper's sec. 3.4.2: "some points on the standard
image deviate from the epipolar line so that the epipolar line does not
intersect the blood vessel"; the distance is eq. 8's, line to point). This
residual carries no correspondence: it is zero wherever the line crosses the
curve, and informative where a curve turns with respect to the epipolar pencil
(the epipolar tangencies) and at the ends.

Objective, for view B's rig correction z (units of the prior sigmas, as in
:class:`recon.pose.calibration_model.ResidualModel`):

    E(z) = sum_k |r_k(z)|^2 / sigma_click^2 + |z|^2
           + sum_i rho(d_i(z) / sigma_curve),

with r_k the clicks' back-projection residuals (eq. 5), d_i the epipolar
distance of traced point i (both directions: A's points against B's curve, B's
against A's) and rho the Cauchy loss rho(u) = c^2 log(1 + u^2 / c^2)
(c = :data:`CURVE_LOSS_SCALE`): a stretch that one view traced and the other did
not (a trace running on past the segment's end, onto a neighbour) costs at most
logarithmically. The traced points are taken every :data:`CURVE_STEP_PX` px (a
trace's error is correlated over a few px, so denser points would count the
same error many times).

Solved by the same parameter-adjusting Levenberg-Marquardt (PALM, Nielsen's
damping rule, :func:`recon.pose.calibration_model.solve_palm`'s loop) with the
Cauchy loss as iteratively re-weighted least squares, started from the
clicks-only full correction. The Jacobian is exact to rounding (complex step;
the nearest curve vertex is chosen on the real part).

The result's posterior is the Laplace covariance of this joint objective at its
minimum (clicks and curve points with their IRLS weights, priors).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from recon.pose.calibration import (
    CalibrationPriors,
    CalibrationResult,
    _checked_points,
    _initial_parameters,
    _result,
    calibrate_supported,
)
from recon.pose.calibration_model import ResidualModel
from recon.pose.uncertainty import PosePosterior, pose_posterior

__all__ = ["CurveResiduals", "calibrate_with_curves", "CURVE_STEP_PX", "CURVE_SIGMA_PX"]

FloatArray = NDArray[np.float64]

CURVE_STEP_PX = 6.0  # one traced point per this much arc length, each view
CURVE_SIGMA_PX = 1.0  # assumed sd of one traced point's epipolar distance
CURVE_LOSS_SCALE = 1.0  # Cauchy scale c, in units of CURVE_SIGMA_PX
_COMPLEX_STEP = 1e-30
_MAX_ITERATIONS = 60


def _subsample(curve_px: FloatArray, step_px: float) -> FloatArray:
    """Points (P, 2) every ``step_px`` of arc length along a polyline (N, 2), ends kept."""
    seg = np.linalg.norm(np.diff(curve_px, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(int(round(s[-1] / step_px)), 1) + 1
    t = np.linspace(0.0, s[-1], n)
    return np.column_stack([np.interp(t, s, curve_px[:, 0]), np.interp(t, s, curve_px[:, 1])])


class CurveResiduals:
    """Epipolar distances (px) of traced points to the other view's curve, for a batch of z.

    ``model`` supplies the pose parametrisation (:meth:`ResidualModel.relative_pose`);
    ``points_a_px`` (Pa, 2) / ``points_b_px`` (Pb, 2) are the subsampled traced points
    whose epipolar lines are tested, ``curve_a_px`` (Na, 2) / ``curve_b_px`` (Nb, 2) the
    dense curves they are tested against.
    """

    def __init__(self, model: ResidualModel, points_a_px: FloatArray, points_b_px: FloatArray,
                 curve_a_px: FloatArray, curve_b_px: FloatArray) -> None:
        self.model = model
        self.pa, self.pb = points_a_px, points_b_px
        self.ca, self.cb = curve_a_px, curve_b_px
        self.n = len(points_a_px) + len(points_b_px)

    @staticmethod
    def _intrinsic(view) -> NDArray:
        """K (3, 3): view-frame point (x, y, z) -> homogeneous pixel (col, row, 1) * z."""
        cx, cy = view.centre_px
        sr, sc = view.pixel_spacing_mm
        return np.array([[view.sid_mm / sc, 0.0, cx], [0.0, view.sid_mm / sr, cy],
                         [0.0, 0.0, 1.0]])

    @staticmethod
    def _rays(points_px: FloatArray, view) -> NDArray:
        """Ray directions (P, 3) in the view's own frame through pixels (P, 2)."""
        cx, cy = view.centre_px
        sr, sc = view.pixel_spacing_mm
        return np.column_stack([(points_px[:, 0] - cx) * sc / view.sid_mm,
                                (points_px[:, 1] - cy) * sr / view.sid_mm,
                                np.ones(len(points_px))])

    @staticmethod
    def _line_distance(lines: NDArray, curve_px: FloatArray) -> NDArray:
        """Distance (M, P) of each line (M, P, 3) to the polyline (N, 2): 0 where it crosses."""
        norm = np.sqrt(lines[..., 0] ** 2 + lines[..., 1] ** 2)
        signed = (lines[..., None, 0] * curve_px[:, 0] + lines[..., None, 1] * curve_px[:, 1]
                  + lines[..., None, 2]) / norm[..., None]  # (M, P, N)
        real = signed.real
        crosses = np.any(np.signbit(real[..., :-1]) != np.signbit(real[..., 1:]), axis=-1)
        j = np.argmin(np.abs(real), axis=-1)
        nearest = np.take_along_axis(signed, j[..., None], axis=-1)[..., 0]
        sign = np.where(nearest.real < 0, -1.0, 1.0)
        return np.where(crosses, 0.0, sign * nearest)

    def distances(self, z: NDArray) -> NDArray:
        """(M, Pa + Pb) epipolar distances (px; A's points in B, then B's in A) for z (M, n)."""
        m = self.model
        R, tr = m.relative_pose(z)  # x_b = R (x_a - tr), A's source at the origin
        Ka, Kb = self._intrinsic(m.view_a), self._intrinsic(m.view_b)
        da = self._rays(self.pa, m.view_a) * m.view_a.sod_mm  # (Pa, 3) points on A's rays
        # A's points: the line in B through the epipole K_b R (0 - tr) and K_b R (X - tr).
        e_b = np.einsum("ij,mjk,mk->mi", Kb, R, -tr)  # (M, 3)
        x_b = np.einsum("ij,mjk,mpk->mpi", Kb, R, da[None] - tr[:, None, :])  # (M, Pa, 3)
        lines_b = np.cross(np.broadcast_to(e_b[:, None, :], x_b.shape), x_b)
        # B's points: X_a = R^T x + tr for x on B's ray; the line in A through K_a tr.
        db = self._rays(self.pb, m.view_b) * m.view_b.sod_mm
        e_a = tr @ Ka.T  # (M, 3)
        x_a = np.einsum("ij,mkj,pk->mpi", Ka, R, db) + e_a[:, None, :]
        lines_a = np.cross(np.broadcast_to(e_a[:, None, :], x_a.shape), x_a)
        return np.concatenate([self._line_distance(lines_b, self.cb),
                               self._line_distance(lines_a, self.ca)], axis=1)

    def distances_and_jacobian(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Distances (P,) and their exact Jacobian (P, n) at z (n,), complex step."""
        n = self.model.n_params
        zc = z[None, :] + 1j * _COMPLEX_STEP * np.eye(n)
        d = self.distances(np.concatenate([z[None, :].astype(complex), zc]))
        return d[0].real.copy(), d[1:].imag.T / _COMPLEX_STEP


def _cauchy_weights(u: FloatArray, c: float) -> FloatArray:
    """IRLS weights of the Cauchy loss c^2 log(1 + u^2 / c^2) at standardised residuals u."""
    return 1.0 / (1.0 + (u / c) ** 2)


def _cauchy_cost(u: FloatArray, c: float) -> float:
    return float(np.sum(c * c * np.log1p((u / c) ** 2)))


def calibrate_with_curves(
    view_a, view_b, points_a_px: ArrayLike, points_b_px: ArrayLike,
    curve_a_px: ArrayLike, curve_b_px: ArrayLike, *,
    priors: CalibrationPriors = CalibrationPriors(),  # noqa: B008 (frozen)
    initial: CalibrationResult | None = None,
    names=None,
    curve_sigma_px: float = CURVE_SIGMA_PX,
    curve_step_px: float = CURVE_STEP_PX,
    loss_scale: float = CURVE_LOSS_SCALE,
    max_iterations: int = _MAX_ITERATIONS,
) -> CalibrationResult:
    """View B's full rig correction from the clicks and the traced curves jointly.

    Parameters
    ----------
    view_a, view_b : header geometries (A the reference, B corrected).
    points_a_px, points_b_px : (K, 2) clicked corresponding features.
    curve_a_px, curve_b_px : (Na, 2), (Nb, 2) the traced centerlines, proximal to distal.
    initial : the clicks-only result to start from (None: computed here by
        :func:`recon.pose.calibration.calibrate_supported` with the full correction); its
        click-noise estimate weights the clicks.
    curve_sigma_px, curve_step_px, loss_scale : the curve term's noise, sampling and
        Cauchy scale (module docstring).

    Returns a :class:`CalibrationResult` with ``correction="curves"``, the joint
    Laplace ``posterior`` and ``decision`` (the curve term's figures).
    """
    start = time.perf_counter()
    pa = _checked_points(points_a_px, "points_a_px")
    pb = _checked_points(points_b_px, "points_b_px")
    ca = _checked_points(curve_a_px, "curve_a_px")
    cb = _checked_points(curve_b_px, "curve_b_px")
    if initial is None or initial.posterior is None:
        initial = calibrate_supported(view_a, view_b, pa, pb, priors=priors, names=names,
                                      candidates=("full",))
    sigma = initial.posterior.click_sigma_px
    unit = ResidualModel(view_a, view_b, pa, pb, np.ones(len(pa)), priors, False)
    model = ResidualModel(view_a, view_b, pa, pb, np.full(len(pa), 1.0 / sigma**2), priors,
                          False)
    curves = CurveResiduals(model, _subsample(ca, curve_step_px), _subsample(cb, curve_step_px),
                            ca, cb)
    z0 = _initial_parameters(model, initial.view_b)

    def cost(z: FloatArray) -> float:
        r = model.residuals(z[None])[0]
        u = curves.distances(z[None])[0] / curve_sigma_px
        return 0.5 * (float(r @ r) + _cauchy_cost(u, loss_scale))

    def linearise(z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Gradient g (n,), Gauss-Newton matrix H (n, n) with the IRLS weights, weights."""
        r, J = model.residuals_and_jacobian(z)
        d, Jd = curves.distances_and_jacobian(z)
        u = d / curve_sigma_px
        w = _cauchy_weights(u, loss_scale)
        Jw = Jd / curve_sigma_px
        g = J.T @ r + Jw.T @ (w * u)
        H = J.T @ J + Jw.T @ (w[:, None] * Jw)
        return g, H, w

    z, c = z0.copy(), cost(z0)
    g, H, w = linearise(z)
    mu, nu, accepted, converged = 1e-6 * float(np.max(np.diag(H))), 2.0, 0, False
    eye = np.eye(model.n_params)
    for _ in range(max_iterations):  # PALM: Nielsen's damping from the gain ratio
        if float(np.max(np.abs(g))) <= 1e-10:
            converged = True
            break
        h = np.linalg.solve(H + mu * eye, -g)
        if float(np.linalg.norm(h)) <= 1e-10 * (float(np.linalg.norm(z)) + 1e-10):
            converged = True
            break
        c_new = cost(z + h)
        predicted = 0.5 * float(h @ (mu * h - g))
        rho = (c - c_new) / predicted if predicted > 0 else -1.0
        if rho > 0:
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
            small = c - c_new <= 1e-12 * c
            z, c = z + h, c_new
            accepted += 1
            g, H, w = linearise(z)
            if small:
                converged = True
                break
        else:
            mu *= nu
            nu *= 2.0
            if mu > 1e30:
                break
    d0 = curves.distances(z0[None])[0]
    d1 = curves.distances(z[None])[0]
    posterior = pose_posterior(unit, z, sigma_px=sigma)
    cov_z = np.linalg.pinv(H, hermitian=True)  # J^T W J of clicks (1/sigma^2), curves, + I
    posterior = PosePosterior(**{**posterior.__dict__, "cov_z": cov_z,
                                 "cov_pose": posterior.pose_map @ cov_z @ posterior.pose_map.T})
    messages = [m for m in initial.warnings if "still" not in m and "implausible" not in m]
    result = _result(unit, z, initial.method, initial.iterations + accepted, converged,
                     np.ones(len(pa)), [f"feature {i + 1}" for i in range(len(pa))]
                     if names is None else list(names), messages, start)
    decision = {
        "rule": "clicks and the traced curves jointly: epipolar distance of every traced "
        f"point (one per {curve_step_px:g} px) to the other view's curve, Cauchy loss "
        f"(scale {loss_scale * curve_sigma_px:g} px), started from the clicks-only full "
        "correction",
        "chosen": "curves",
        "click_sigma_px": sigma,
        "curve_points": int(curves.n),
        "curve_median_px": {"before": float(np.median(np.abs(d0))),
                            "after": float(np.median(np.abs(d1)))},
        "curve_p90_px": {"before": float(np.percentile(np.abs(d0), 90)),
                         "after": float(np.percentile(np.abs(d1), 90))},
        "curve_outlier_fraction": float(np.mean(w < 0.5)),
        "clicks_only": initial.decision,
    }
    return replace(result, correction="curves", posterior=posterior, decision=decision)
