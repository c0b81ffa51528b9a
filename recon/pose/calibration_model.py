"""The model behind calibration: eq. (5)'s residuals, the priors, and the three solvers.

:class:`CalibrationPriors` holds the prior sigmas of view B's correction. The
residual model evaluates eq. (5) for a batch of parameter vectors at once
(vectorised and complex-step safe, so the Jacobian is exact to rounding).
The solvers, PALM (ours, default), scipy's MINPACK LM and dual annealing,
are described in :mod:`recon.pose.calibration`, which is the public entry point.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import dual_annealing, least_squares

from recon.errors import CoronaryError
from recon.geometry import ViewGeometry

FloatArray = NDArray[np.float64]

ANNEAL_MAX_ITERATIONS = 50
ANNEAL_ROTATION_BOUND_DEG = 4.0
ANNEAL_TRANSLATION_BOUND_MM = 40.0
ANNEAL_SEED = 0
_PALM_TAU = 1e-6  # mu_0 = tau max diag(J^T J); the header is close: start near Gauss-Newton
_XTOL = 1e-10  # step, relative to the parameters (sigma units)
_FTOL = 1e-12  # relative cost decrease
_GTOL = 1e-10  # gradient, px^2 per sigma
_COMPLEX_STEP = 1e-30


class CalibrationError(CoronaryError):
    """Corresponding points or options that cannot calibrate; one line naming the problem."""


@dataclass(frozen=True)
class CalibrationPriors:
    """How far the header may plausibly be off: the one place these magnitudes are set.

    Each prior adds a residual (parameter / sigma) in pixels, so one sigma of
    correction costs as much as one pixel of back-projection error.

    Attributes
    ----------
    rotation_sigma_deg : rotation of B's rig (each rotation-vector component).
    translation_sigma_mm : (3,) translation of B's rig along view B's (u, v, d)
        axes; the SOD error lies along d.
    sid_sigma_mm : SID of each view (only with ``estimate_intrinsics``).
    principal_sigma_px : principal point (col, row) of each view (idem).
    """

    rotation_sigma_deg: float = 1.5
    translation_sigma_mm: tuple[float, float, float] = (5.0, 5.0, 10.0)
    sid_sigma_mm: float = 10.0
    principal_sigma_px: float = 5.0

    def __post_init__(self) -> None:
        values = [
            self.rotation_sigma_deg,
            *self.translation_sigma_mm,
            self.sid_sigma_mm,
            self.principal_sigma_px,
        ]
        if len(self.translation_sigma_mm) != 3 or not all(np.isfinite(x) and x > 0 for x in values):
            raise CalibrationError(f"calibration priors must be positive and finite, got {self}")


# ----------------------------------------------------------------- the model
def _rotation_batch(r: NDArray) -> NDArray:
    """Rotations (M, 3, 3) from rotation vectors (M, 3); analytic in r (complex-step safe).

    R = I + A(s) [r]x + B(s) [r]x^2 with s = r.r, A = sin(th)/th,
    B = (1 - cos th)/th^2 written as functions of s (series near 0).
    """
    s = np.sum(r * r, axis=1)
    small = np.abs(s) < 1e-6
    s_safe = np.where(small, 1.0, s)
    th = np.sqrt(s_safe)
    a = np.where(small, 1.0 - s / 6.0 + s * s / 120.0, np.sin(th) / th)
    half = np.sin(th / 2.0)
    b = np.where(small, 0.5 - s / 24.0 + s * s / 720.0, 2.0 * half * half / s_safe)
    zero = np.zeros_like(s)
    kx = np.stack(
        [
            np.stack([zero, -r[:, 2], r[:, 1]], axis=1),
            np.stack([r[:, 2], zero, -r[:, 0]], axis=1),
            np.stack([-r[:, 1], r[:, 0], zero], axis=1),
        ],
        axis=1,
    )
    kx2 = kx @ kx
    return np.eye(3) + a[:, None, None] * kx + b[:, None, None] * kx2


class ResidualModel:
    """Eq. (5) residuals for a batch of parameter vectors; vectorised, complex-step safe.

    Internal parameters z are in units of the prior sigmas: rotvec = s_r z[0:3],
    t = T z[3:3+n_t], then (with intrinsics) dSID_A, dcx_A, dcy_A, dSID_B,
    dcx_B, dcy_B in units of their sigmas.
    """

    def __init__(
        self,
        view_a: ViewGeometry,
        view_b: ViewGeometry,
        points_a_px: FloatArray,
        points_b_px: FloatArray,
        weights: FloatArray,
        priors: CalibrationPriors | None,
        estimate_intrinsics: bool,
    ) -> None:
        scale = priors if priors is not None else CalibrationPriors()
        self.view_a, self.view_b = view_a, view_b
        self.pa, self.pb = points_a_px, points_b_px
        self.sqrt_w = np.sqrt(weights)
        self.has_priors = priors is not None
        self.intrinsics = estimate_intrinsics
        self.sigma_rot_rad = np.deg2rad(scale.rotation_sigma_deg)
        self.sigma_sid_mm = scale.sid_sigma_mm
        self.sigma_pp_px = scale.principal_sigma_px
        axes_b = view_b.R_view_from_world  # rows u, v, d of B in world
        T = axes_b.T * np.asarray(scale.translation_sigma_mm)[None, :]  # t = T z_t
        if priors is None:
            # Hold the baseline length: t . n = 0 with n the header's baseline direction.
            n = view_b.source_world - view_a.source_world
            c = T.T @ (n / np.linalg.norm(n))
            basis = np.linalg.svd(c[None, :])[2][1:].T  # (3, 2), orthonormal, c^T basis = 0
            T = T @ basis
        self.T = T
        self.n_t = T.shape[1]
        self.n_params = 3 + self.n_t + (6 if estimate_intrinsics else 0)
        self.n_features = len(points_a_px)
        self.Ra = view_a.R_view_from_world
        self.Sa = view_a.source_world
        self.Rb0 = view_b.R_view_from_world
        self.Sb0 = view_b.source_world
        self.spacing_a = np.array(view_a.pixel_spacing_mm[::-1])  # (sc, sr)
        self.spacing_b = np.array(view_b.pixel_spacing_mm[::-1])

    # ------------------------------------------------------------ mapping
    def pose(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Rotation vector (3,) rad and translation (3,) mm of internal parameters z (n,)."""
        z = np.asarray(z, dtype=float)
        return self.sigma_rot_rad * z[:3], self.T @ z[3 : 3 + self.n_t]

    def views(self, z: FloatArray) -> tuple[ViewGeometry, ViewGeometry]:
        """Calibrated (view A, view B) for internal parameters z (n,)."""
        rotvec, t_mm = self.pose(z)
        view_a = self.view_a
        view_b = self.view_b.with_correction(rotvec, t_mm)
        if self.intrinsics:
            d = z[3 + self.n_t :]
            view_a = _with_intrinsics(view_a, d[0:3], self.sigma_sid_mm, self.sigma_pp_px)
            view_b = _with_intrinsics(view_b, d[3:6], self.sigma_sid_mm, self.sigma_pp_px)
        return view_a, view_b

    def _intrinsics(self, z: NDArray, view: ViewGeometry, k: int) -> tuple[NDArray, ...]:
        """SID (M, 1) and principal point (M, 1) x 2 of one view for a batch z (M, n)."""
        cx, cy = view.centre_px
        if not self.intrinsics:
            return (np.asarray(view.sid_mm), np.asarray(cx), np.asarray(cy))
        j = 3 + self.n_t + 3 * k
        return (
            view.sid_mm + self.sigma_sid_mm * z[:, j : j + 1],
            cx + self.sigma_pp_px * z[:, j + 1 : j + 2],
            cy + self.sigma_pp_px * z[:, j + 2 : j + 3],
        )

    def relative_pose(self, z: NDArray) -> tuple[NDArray, NDArray]:
        """Eq. (1) for a batch z (M, n): rotation R (M, 3, 3) from A's view frame to B's
        and B's source tr (M, 3) in A's view frame (origin at A's source), so a point
        x_a of A's frame is x_b = R (x_a - tr) in B's."""
        rotvec = self.sigma_rot_rad * z[:, :3]
        t = z[:, 3 : 3 + self.n_t] @ self.T.T  # (M, 3)
        Rn = _rotation_batch(rotvec)  # (M, 3, 3) correction rotation
        Rb = np.einsum("ij,mkj->mik", self.Rb0, Rn)  # R_b = R_b0 Rn^T
        Sb = np.einsum("mij,j->mi", Rn, self.Sb0) + t  # B's source (M, 3)
        return Rb @ self.Ra.T, (Sb - self.Sa) @ self.Ra.T

    # ------------------------------------------------------------ eq. (5)
    def project_pairs(self, z: NDArray) -> tuple[NDArray, NDArray]:
        """Back-projections (M, K, 2) into A and into B of the features triangulated under z (M, n).

        Triangulation by eqs. (2)-(3) in view A's frame, as in
        :func:`recon.geometry.triangulate_paper`, written for a batch of poses.
        """
        R, tr = self.relative_pose(z)  # eq. (1)
        sid_a, cx_a, cy_a = self._intrinsics(z, self.view_a, 0)
        sid_b, cx_b, cy_b = self._intrinsics(z, self.view_b, 1)
        sc_a, sr_a = self.spacing_a
        sc_b, sr_b = self.spacing_b
        # normalised coordinates (M, K)
        xi_a = (self.pa[:, 0] - cx_a) * sc_a / sid_a
        eta_a = (self.pa[:, 1] - cy_a) * sr_a / sid_a
        xi_b = (self.pb[:, 0] - cx_b) * sc_b / sid_b
        eta_b = (self.pb[:, 1] - cy_b) * sr_b / sid_b
        shape = np.broadcast_shapes(np.shape(xi_a), np.shape(xi_b), (len(z), self.n_features))
        xi_a, eta_a, xi_b, eta_b = (np.broadcast_to(x, shape) for x in (xi_a, eta_a, xi_b, eta_b))
        # eq. (2): vectors a, b per feature, components first: (3, M, K)
        a = R[:, 0, :].T[:, :, None] - xi_b[None] * R[:, 2, :].T[:, :, None]
        b = R[:, 1, :].T[:, :, None] - eta_b[None] * R[:, 2, :].T[:, :, None]
        trc = tr.T[:, :, None]  # (3, M, 1)
        at = np.sum(a * trc, axis=0)
        bt = np.sum(b * trc, axis=0)
        # eq. (3): C = (A^T A)^-1 A^T B, rows of A (1, 0, -xi_a), (0, 1, -eta_a), a, b
        m00 = a[0] * a[0] + b[0] * b[0] + 1.0
        m01 = a[0] * a[1] + b[0] * b[1]
        m02 = a[0] * a[2] + b[0] * b[2] - xi_a
        m11 = a[1] * a[1] + b[1] * b[1] + 1.0
        m12 = a[1] * a[2] + b[1] * b[2] - eta_a
        m22 = a[2] * a[2] + b[2] * b[2] + xi_a * xi_a + eta_a * eta_a
        rhs = a * at + b * bt  # (3, M, K)
        X = _solve_sym3(m00, m01, m02, m11, m12, m22, rhs)  # A's view frame (3, M, K)
        proj_a = np.stack(
            [
                cx_a + sid_a * X[0] / (X[2] * sc_a),
                cy_a + sid_a * X[1] / (X[2] * sr_a),
            ],
            axis=-1,
        )
        d = X - trc
        xb = [
            R[:, i, 0, None] * d[0] + R[:, i, 1, None] * d[1] + R[:, i, 2, None] * d[2]
            for i in range(3)
        ]
        proj_b = np.stack(
            [
                cx_b + sid_b * xb[0] / (xb[2] * sc_b),
                cy_b + sid_b * xb[1] / (xb[2] * sr_b),
            ],
            axis=-1,
        )
        return proj_a, proj_b

    def image_residuals(self, z: NDArray) -> NDArray:
        """Unweighted residuals (M, K, 4): back-projection minus click, (col, row) in A then B."""
        proj_a, proj_b = self.project_pairs(z)
        return np.concatenate([proj_a - self.pa, proj_b - self.pb], axis=-1)

    def residuals(self, z: NDArray, feature_weights: FloatArray | None = None) -> NDArray:
        """Residual vectors (M, 4K [+ n]) of eq. (5) plus the priors, for a batch z (M, n)."""
        r = self.image_residuals(z)
        sw = self.sqrt_w if feature_weights is None else self.sqrt_w * np.sqrt(feature_weights)
        r = (r * sw[:, None]).reshape(len(z), -1)
        if self.has_priors:
            r = np.concatenate([r, z], axis=1)  # priors: z is parameter / sigma, 1 px each
        return r

    def residuals_and_jacobian(
        self, z: FloatArray, feature_weights: FloatArray | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """Residuals (m,) and exact Jacobian (m, n) at z (n,) by complex-step differentiation."""
        n = self.n_params
        zc = z[None, :] + 1j * _COMPLEX_STEP * np.eye(n)
        rc = self.residuals(zc, feature_weights)
        return rc[0].real.copy(), rc.imag.T / _COMPLEX_STEP

    def distances(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Back-projection distances (M, K, 2) in px and on the detector in mm, views (A, B).

        ``z`` is one parameter vector (n,) or a batch (M, n); the output then has no M axis
        for a single vector.
        """
        z = np.asarray(z, dtype=float)
        r = self.image_residuals(np.atleast_2d(z))
        px = np.stack([np.hypot(r[..., 0], r[..., 1]), np.hypot(r[..., 2], r[..., 3])], axis=-1)
        ra = r[..., 0:2] * self.spacing_a
        rb = r[..., 2:4] * self.spacing_b
        mm = np.stack([np.hypot(ra[..., 0], ra[..., 1]), np.hypot(rb[..., 0], rb[..., 1])], axis=-1)
        if z.ndim == 1:
            return px[0], mm[0]
        return px, mm


def _solve_sym3(
    a: NDArray, b: NDArray, c: NDArray, d: NDArray, e: NDArray, f: NDArray, rhs: NDArray
) -> NDArray:
    """Solve symmetric 3x3 systems [[a, b, c], [b, d, e], [c, e, f]] x = rhs by the adjugate.

    Entries are arrays of one shape S, rhs is (3, *S); returns x (3, *S).
    """
    c00 = d * f - e * e
    c01 = c * e - b * f
    c02 = b * e - c * d
    c11 = a * f - c * c
    c12 = b * c - a * e
    c22 = a * d - b * b
    inv_det = 1.0 / (a * c00 + b * c01 + c * c02)
    x0, x1, x2 = rhs
    return np.stack(
        [
            (c00 * x0 + c01 * x1 + c02 * x2) * inv_det,
            (c01 * x0 + c11 * x1 + c12 * x2) * inv_det,
            (c02 * x0 + c12 * x1 + c22 * x2) * inv_det,
        ]
    )


def _with_intrinsics(
    view: ViewGeometry, dz: FloatArray, sigma_sid_mm: float, sigma_pp_px: float
) -> ViewGeometry:
    """The view with SID and principal point moved by dz (3,) in sigma units."""
    return replace(
        view,
        sid_mm=view.sid_mm + sigma_sid_mm * float(dz[0]),
        principal_offset_px=(
            view.principal_offset_px[0] + sigma_pp_px * float(dz[1]),
            view.principal_offset_px[1] + sigma_pp_px * float(dz[2]),
        ),
    )


def _huber_weights(e: FloatArray, scale_px: float) -> FloatArray:
    """IRLS weights (K,) of the Huber loss for per-feature residual norms e (K,)."""
    return np.where(e <= scale_px, 1.0, scale_px / np.maximum(e, 1e-300))


def _huber_cost(e: FloatArray, scale_px: float, w: FloatArray) -> float:
    """Sum over features of w rho(e), rho(e) = e^2 inside the scale, 2 s e - s^2 outside."""
    rho = np.where(e <= scale_px, e * e, 2.0 * scale_px * e - scale_px * scale_px)
    return float(np.sum(w * rho))


# --------------------------------------------------------------- optimisers
@dataclass
class Solution:
    z: FloatArray
    iterations: int
    converged: bool


def solve_palm(
    model: ResidualModel, z0: FloatArray, max_iterations: int, loss: str, loss_scale_px: float
) -> Solution:
    """Parameter-adjusting LM (Nielsen's damping rule), optionally with Huber IRLS."""
    robust = loss == "huber"
    K = model.n_features

    def cost_and_weights(z: FloatArray, r: FloatArray | None = None) -> tuple[float, FloatArray]:
        if not robust:
            if r is None:
                r = model.residuals(z[None])[0]
            return 0.5 * float(r @ r), np.ones(K)
        res = model.image_residuals(z[None])[0]  # (K, 4)
        e = np.sqrt(np.sum(res * res, axis=1))
        prior = float(z @ z) if model.has_priors else 0.0
        cost = 0.5 * (_huber_cost(e, loss_scale_px, model.sqrt_w**2) + prior)
        return cost, _huber_weights(e, loss_scale_px)

    z = z0.copy()
    cost, irls = cost_and_weights(z)
    r, J = model.residuals_and_jacobian(z, irls if robust else None)
    if not robust:
        cost = 0.5 * float(r @ r)
    g = J.T @ r
    H = J.T @ J
    mu = _PALM_TAU * float(np.max(np.diag(H)))
    nu = 2.0
    eye = np.eye(model.n_params)
    accepted = 0
    for _ in range(max_iterations):
        if cost <= 1e-26 or float(np.max(np.abs(g))) <= _GTOL:
            return Solution(z, accepted, True)
        h = np.linalg.solve(H + mu * eye, -g)
        small_step = float(np.linalg.norm(h)) <= _XTOL * (float(np.linalg.norm(z)) + _XTOL)
        if small_step:
            return Solution(z, accepted, True)
        z_new = z + h
        cost_new, irls_new = cost_and_weights(z_new)
        predicted = 0.5 * float(h @ (mu * h - g))  # L(0) - L(h) of the damped model
        rho = (cost - cost_new) / predicted if predicted > 0 else -1.0
        if rho > 0:
            # PALM: damping adjusted from the gain ratio (Nielsen's rule).
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
            small_gain = cost - cost_new <= _FTOL * cost
            z, cost, irls = z_new, cost_new, irls_new
            accepted += 1
            if small_gain:
                return Solution(z, accepted, True)
            r, J = model.residuals_and_jacobian(z, irls if robust else None)
            g = J.T @ r
            H = J.T @ J
        else:
            mu *= nu
            nu *= 2.0
            if not np.isfinite(mu) or mu > 1e30:
                return Solution(z, accepted, False)
    return Solution(z, accepted, False)


def solve_lm(model: ResidualModel, z0: FloatArray, max_iterations: int) -> Solution:
    """scipy's MINPACK Levenberg-Marquardt (the paper's Optimize 2), same exact Jacobian."""

    def fun(z: FloatArray) -> FloatArray:
        return model.residuals(z[None])[0]

    def jac(z: FloatArray) -> FloatArray:
        return model.residuals_and_jacobian(z)[1]

    res = least_squares(
        fun,
        z0,
        jac=jac,
        method="lm",
        xtol=_XTOL,
        ftol=_FTOL,
        gtol=_GTOL,
        max_nfev=max_iterations * (model.n_params + 1),
    )
    return Solution(res.x, int(res.njev or res.nfev), bool(res.status > 0))


def solve_anneal(
    model: ResidualModel, z0: FloatArray, max_iterations: int, loss: str, loss_scale_px: float
) -> Solution:
    """scipy's dual annealing (the paper's Optimize 1) on the same cost, within fixed bounds."""
    robust = loss == "huber"

    def cost(z: FloatArray) -> float:
        if robust:
            res = model.image_residuals(z[None])[0]
            e = np.sqrt(np.sum(res * res, axis=1))
            prior = float(z @ z) if model.has_priors else 0.0
            return 0.5 * (_huber_cost(e, loss_scale_px, model.sqrt_w**2) + prior)
        r = model.residuals(z[None])[0]
        return 0.5 * float(r @ r)

    def grad(z: FloatArray) -> FloatArray:
        if robust:
            e = np.linalg.norm(model.image_residuals(z[None])[0], axis=1)
            r, J = model.residuals_and_jacobian(z, _huber_weights(e, loss_scale_px))
        else:
            r, J = model.residuals_and_jacobian(z)
        return J.T @ r

    rot = ANNEAL_ROTATION_BOUND_DEG / np.rad2deg(model.sigma_rot_rad)
    # translation bound: +-40 mm along each direction spanned by T's columns
    trans = ANNEAL_TRANSLATION_BOUND_MM / np.linalg.norm(model.T, axis=0)
    bounds = [(-rot, rot)] * 3 + [(-b, b) for b in trans]
    bounds += [(-3.0, 3.0)] * (model.n_params - len(bounds))
    lo = np.array([b[0] for b in bounds])
    hi = np.array([b[1] for b in bounds])
    res = dual_annealing(
        cost,
        bounds,
        maxiter=max(1, min(max_iterations, ANNEAL_MAX_ITERATIONS)),
        seed=ANNEAL_SEED,
        x0=np.clip(z0, lo, hi),
        minimizer_kwargs={"method": "L-BFGS-B", "jac": grad},
    )
    return Solution(np.asarray(res.x, dtype=float), int(res.nit), bool(res.success))
