"""Two-view geometry calibration: the paper's sec. 3.2, objective eq. (5), solved by PALM.

View A is the reference (its header defines the world); view B's header is
off by a degree or two, about a centimetre of SOD and a few millimetres of
table shift. All of this is one rigid motion of B's whole rig, estimated as
a rotation vector ``rotvec`` (rad, about the isocenter) and a translation
``t_mm`` and applied with :meth:`ViewGeometry.with_correction`. Optionally
(``estimate_intrinsics=True``) the SID and the principal point of both views
are refined too.

Objective, eq. (5): each corresponding feature i is triangulated with the
paper's least-squares rule (eqs. 2-3, :func:`recon.geometry.triangulate`,
method "paper") using the current view B, then projected back into both
views; the residuals are the 2D differences to the clicked points (4 per
feature) plus soft priors (parameter / sigma, one pixel of residual per
sigma, see :class:`CalibrationPriors`).

Observability. The back-projection error is unchanged when the whole scene
and B's source are scaled about A's source (B's images do not change), so a
translation of B's rig along the baseline (A's source -> B's source) cannot
be seen from correspondences: only 5 of the 6 pose parameters are
observable (rotation, and the translation across the baseline). With
priors the baseline length is fixed by the prior (the least surprising pose
that explains the clicks); with ``priors=None`` it is held at the header's
value (the translation is restricted to the plane across the header's
baseline). Each feature constrains roughly one observable parameter (its
epipolar distance), so the rule for the number of features K is:
K >= 2 with priors (K < 5 adds an "underdetermined" warning, the priors
fix the rest) and K >= 5 without priors.

Methods
-------
"palm" (ours, default)
    Levenberg-Marquardt with the damping mu adjusted from the gain ratio
    rho = actual reduction / predicted reduction (the paper's sec. 3.2 and
    its ref. [20], Qi Yanli's parameter-adjusting LM). The rule used is
    Nielsen's: on success mu *= max(1/3, 1 - (2 rho - 1)^3) and nu = 2; on
    failure mu *= nu, nu *= 2; mu_0 = tau * max diag(J^T J), tau = 1e-6
    (H. B. Nielsen, "Damping parameter in Marquardt's method", IMM-REP-1999-05;
    K. Madsen, H. B. Nielsen, O. Tingleff, "Methods for non-linear least
    squares problems", 2004, Algorithm 3.16). The Jacobian is exact to
    rounding (complex-step differentiation, all parameters in one vectorised
    evaluation). A robust ``loss="huber"`` is solved by IRLS weights per
    feature inside the same loop.
"lm"
    ``scipy.optimize.least_squares(method="lm")`` (MINPACK), the paper's
    Optimize 2, with the same residuals and the same exact Jacobian.
"anneal"
    ``scipy.optimize.dual_annealing`` on the same cost within bounds of
    +-4 degrees and +-40 mm (the paper's Optimize 1), fixed seed, at most
    ``min(max_iterations, 50)`` global iterations.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import dual_annealing, least_squares

from recon.errors import CoronaryError
from recon.geometry import ViewGeometry, rotvec_from_rotation, view_separation_deg

__all__ = [
    "CalibrationError",
    "CalibrationPriors",
    "CalibrationResult",
    "calibrate",
    "refine_with_matches",
    "backprojection_residuals_px",
    "METHODS",
]

FloatArray = NDArray[np.float64]

METHODS = ("palm", "lm", "anneal")
LOSSES = ("linear", "huber")
MIN_SEPARATION_DEG = 15.0  # below this the two views are nearly parallel: warn
MIN_FEATURES_WITH_PRIORS = 2
MIN_FEATURES_WITHOUT_PRIORS = 5  # 5 observable pose parameters, ~1 constraint per feature
LARGE_RESIDUAL_PX = 5.0  # a feature this far off after calibration is reported
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


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """Outcome of :func:`calibrate`.

    Attributes
    ----------
    view_b : calibrated view B (header + the rigid correction; new SID and
        principal point when intrinsics were estimated).
    rotvec : (3,) rotation vector (rad) of the correction applied to the input
        view B (about its isocenter).
    t_mm : (3,) translation (mm) of that correction, world frame.
    method : "palm", "lm" or "anneal".
    iterations : accepted steps (palm), Jacobian evaluations (lm), global
        iterations (anneal).
    elapsed_ms : wall time of the optimisation (validation included).
    error_before_px, error_after_px : mean back-projection distance per
        feature per view (eq. 5 summed over features, divided by 2K), in px.
    error_before_mm, error_after_mm : the same measured on the detector
        (px * pixel spacing), the unit of the paper's Table 2.
    converged : a convergence test was met before ``max_iterations``.
    n_features : K.
    warnings : one-line messages (ill-conditioned views, underdetermined,
        features still far off, ...).
    view_a : view A (new SID and principal point only if intrinsics were
        estimated, otherwise the input view A).
    residuals_px : (K, 2) back-projection distance of each feature in (A, B)
        after calibration.
    """

    view_b: ViewGeometry
    rotvec: FloatArray
    t_mm: FloatArray
    method: str
    iterations: int
    elapsed_ms: float
    error_before_px: float
    error_after_px: float
    error_before_mm: float
    error_after_mm: float
    converged: bool
    n_features: int
    warnings: tuple[str, ...] = ()
    view_a: ViewGeometry | None = None
    residuals_px: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))


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


class _Model:
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

    # ------------------------------------------------------------ eq. (5)
    def project_pairs(self, z: NDArray) -> tuple[NDArray, NDArray]:
        """Back-projections (M, K, 2) into A and into B of the features triangulated under z (M, n).

        Triangulation by eqs. (2)-(3) in view A's frame, as in
        :func:`recon.geometry.triangulate_paper`, written for a batch of poses.
        """
        rotvec = self.sigma_rot_rad * z[:, :3]
        t = z[:, 3 : 3 + self.n_t] @ self.T.T  # (M, 3)
        Rn = _rotation_batch(rotvec)  # (M, 3, 3) correction rotation
        Rb = np.einsum("ij,mkj->mik", self.Rb0, Rn)  # R_b = R_b0 Rn^T
        Sb = np.einsum("mij,j->mi", Rn, self.Sb0) + t  # B's source (M, 3)
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
        R = Rb @ self.Ra.T  # eq. (1): relative rotation (M, 3, 3)
        tr = (Sb - self.Sa) @ self.Ra.T  # B's source in A's frame (M, 3)
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
class _Solution:
    z: FloatArray
    iterations: int
    converged: bool


def _palm(
    model: _Model, z0: FloatArray, max_iterations: int, loss: str, loss_scale_px: float
) -> _Solution:
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
            return _Solution(z, accepted, True)
        h = np.linalg.solve(H + mu * eye, -g)
        small_step = float(np.linalg.norm(h)) <= _XTOL * (float(np.linalg.norm(z)) + _XTOL)
        if small_step:
            return _Solution(z, accepted, True)
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
                return _Solution(z, accepted, True)
            r, J = model.residuals_and_jacobian(z, irls if robust else None)
            g = J.T @ r
            H = J.T @ J
        else:
            mu *= nu
            nu *= 2.0
            if not np.isfinite(mu) or mu > 1e30:
                return _Solution(z, accepted, False)
    return _Solution(z, accepted, False)


def _scipy_lm(model: _Model, z0: FloatArray, max_iterations: int) -> _Solution:
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
    return _Solution(res.x, int(res.njev or res.nfev), bool(res.status > 0))


def _anneal(
    model: _Model, z0: FloatArray, max_iterations: int, loss: str, loss_scale_px: float
) -> _Solution:
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
    return _Solution(np.asarray(res.x, dtype=float), int(res.nit), bool(res.success))


# ------------------------------------------------------------- validation
def _checked_points(points: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(points, dtype=float)
    if arr.ndim == 1 and arr.size == 0:
        arr = arr.reshape(0, 2)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise CalibrationError(f"{name} must have shape (K, 2), got {arr.shape}")
    return arr


def _validate(
    view_a: ViewGeometry,
    view_b: ViewGeometry,
    points_a_px: ArrayLike,
    points_b_px: ArrayLike,
    weights: ArrayLike | None,
    names: Sequence[str] | None,
    method: str,
    priors: CalibrationPriors | None,
    estimate_intrinsics: bool,
    max_iterations: int,
    loss: str,
    loss_scale_px: float,
) -> tuple[FloatArray, FloatArray, FloatArray, list[str]]:
    if method not in METHODS:
        raise CalibrationError(f"unknown calibration method {method!r} (use one of {METHODS})")
    if loss not in LOSSES:
        raise CalibrationError(f"unknown loss {loss!r} (use one of {LOSSES})")
    if loss == "huber" and method == "lm":
        raise CalibrationError("loss='huber' needs method 'palm' or 'anneal' (MINPACK LM is plain)")
    if not (np.isfinite(loss_scale_px) and loss_scale_px > 0):
        raise CalibrationError(f"loss_scale_px must be positive, got {loss_scale_px!r}")
    if max_iterations < 1:
        raise CalibrationError(f"max_iterations must be at least 1, got {max_iterations}")
    if estimate_intrinsics and priors is None:
        raise CalibrationError("estimate_intrinsics=True needs priors (SID and centre are weak)")
    pa = _checked_points(points_a_px, "points_a_px")
    pb = _checked_points(points_b_px, "points_b_px")
    if len(pa) != len(pb):
        raise CalibrationError(
            f"feature counts differ: {len(pa)} points in view A, {len(pb)} in view B"
        )
    k = len(pa)
    labels = [f"feature {i + 1}" for i in range(k)] if names is None else [str(x) for x in names]
    if len(labels) != k:
        raise CalibrationError(f"{len(labels)} names given for {k} features")
    for view_name, view, pts in (("A", view_a, pa), ("B", view_b, pb)):
        bad = ~np.all(np.isfinite(pts), axis=1)
        if np.any(bad):
            i = int(np.argmax(bad))
            raise CalibrationError(f"{labels[i]}: point in view {view_name} is not finite")
        outside = (
            (pts[:, 0] < -0.5)
            | (pts[:, 0] > view.cols - 0.5)
            | (pts[:, 1] < -0.5)
            | (pts[:, 1] > view.rows - 0.5)
        )
        if np.any(outside):
            i = int(np.argmax(outside))
            raise CalibrationError(
                f"{labels[i]}: point ({pts[i, 0]:.1f}, {pts[i, 1]:.1f}) lies outside view "
                f"{view_name}'s {view.cols}x{view.rows} image"
            )
    if weights is None:
        w = np.ones(k)
    else:
        w = np.asarray(weights, dtype=float)
        if w.shape != (k,):
            raise CalibrationError(f"weights must have shape ({k},), got {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise CalibrationError("weights must be finite and non-negative")
    k_used = int(np.count_nonzero(w > 0))
    need = MIN_FEATURES_WITH_PRIORS if priors is not None else MIN_FEATURES_WITHOUT_PRIORS
    if k_used < need:
        rule = "with priors" if priors is not None else "without priors"
        raise CalibrationError(
            f"calibration needs at least {need} corresponding features {rule}, got {k_used}"
        )
    return pa, pb, w, labels


# ------------------------------------------------------------------ public
def calibrate(
    view_a: ViewGeometry,
    view_b: ViewGeometry,
    points_a_px: ArrayLike,
    points_b_px: ArrayLike,
    *,
    method: str = "palm",
    priors: CalibrationPriors | None = CalibrationPriors(),  # noqa: B008 (frozen)
    weights: ArrayLike | None = None,
    estimate_intrinsics: bool = False,
    max_iterations: int = 200,
    loss: str = "linear",
    loss_scale_px: float = 2.0,
    initial_view_b: ViewGeometry | None = None,
    names: Sequence[str] | None = None,
) -> CalibrationResult:
    """Calibrate view B's rig against view A from corresponding points (eq. 5).

    Parameters
    ----------
    view_a, view_b : header geometries; A is the reference, B gets the rigid
        correction (the priors are centred on this ``view_b``).
    points_a_px, points_b_px : (K, 2) corresponding (col, row) pixels.
    method : "palm" (default), "lm" or "anneal" (see the module docstring).
    priors : soft priors; ``None`` removes them (then the baseline length is
        held at the header's and K >= 5 features are needed).
    weights : (K,) non-negative weights of the features (default 1).
    estimate_intrinsics : also refine SID and principal point of both views.
    max_iterations : iteration limit (anneal: at most 50 global iterations).
    loss : "linear" or "huber" (robust; IRLS per feature, not for "lm").
    loss_scale_px : Huber scale, per-feature residual norm in px.
    initial_view_b : start from this geometry of B (e.g. an earlier result)
        instead of ``view_b``; must share view B's angles and spacing.
    names : (K,) labels for the messages (default "feature i").

    Returns
    -------
    CalibrationResult

    Raises
    ------
    CalibrationError
        Fewer than 2 features (5 without priors), mismatched counts, NaN,
        points outside the image, bad options.
    """
    start = time.perf_counter()
    pa, pb, w, labels = _validate(
        view_a, view_b, points_a_px, points_b_px, weights, names, method, priors,
        estimate_intrinsics, max_iterations, loss, loss_scale_px,
    )  # fmt: skip
    model = _Model(view_a, view_b, pa, pb, w, priors, estimate_intrinsics)
    z0 = np.zeros(model.n_params)
    if initial_view_b is not None:
        z0 = _initial_parameters(model, initial_view_b)
    messages: list[str] = []
    separation = view_separation_deg(view_a, view_b)
    if separation < MIN_SEPARATION_DEG:
        messages.append(
            f"ill-conditioned: views are only {separation:.1f} deg apart "
            f"(< {MIN_SEPARATION_DEG:.0f}); depth and calibration are unreliable"
        )
    k_used = int(np.count_nonzero(w > 0))
    if k_used < MIN_FEATURES_WITHOUT_PRIORS:
        messages.append(
            f"underdetermined: {k_used} features constrain fewer than the 5 observable pose "
            "parameters; the priors fix the rest"
        )
    if method == "palm":
        sol = _palm(model, z0, max_iterations, loss, loss_scale_px)
    elif method == "lm":
        sol = _scipy_lm(model, z0, max_iterations)
    else:
        sol = _anneal(model, z0, max_iterations, loss, loss_scale_px)
    if not sol.converged:
        messages.append(f"{method} did not converge in {max_iterations} iterations")
    if not np.all(np.isfinite(sol.z)):
        raise CalibrationError(f"{method} diverged (non-finite parameters); check the clicks")
    zero = np.zeros(model.n_params)
    (dist_before, dist_after), (mm_before, mm_after) = model.distances(np.stack([zero, sol.z]))
    far = np.max(dist_after, axis=1) > LARGE_RESIDUAL_PX
    for i in np.flatnonzero(far & (w > 0))[:5]:
        messages.append(
            f"{labels[i]} is still {np.max(dist_after[i]):.1f} px off after calibration; "
            "check the click"
        )
    rotvec, t_mm = model.pose(sol.z)
    rot_deg = float(np.rad2deg(np.linalg.norm(rotvec)))
    if rot_deg > ANNEAL_ROTATION_BOUND_DEG or float(np.linalg.norm(t_mm)) > 2 * (
        ANNEAL_TRANSLATION_BOUND_MM
    ):
        messages.append(
            f"implausible correction: {rot_deg:.1f} deg and {np.linalg.norm(t_mm):.1f} mm "
            "(header errors are expected below a few degrees and centimetres)"
        )
    cal_a, cal_b = model.views(sol.z)
    used = w > 0
    return CalibrationResult(
        view_b=cal_b,
        rotvec=rotvec,
        t_mm=t_mm,
        method=method,
        iterations=sol.iterations,
        elapsed_ms=(time.perf_counter() - start) * 1e3,
        error_before_px=float(np.mean(dist_before[used])),
        error_after_px=float(np.mean(dist_after[used])),
        error_before_mm=float(np.mean(mm_before[used])),
        error_after_mm=float(np.mean(mm_after[used])),
        converged=sol.converged,
        n_features=len(pa),
        warnings=tuple(messages),
        view_a=cal_a,
        residuals_px=dist_after,
    )


def _initial_parameters(model: _Model, initial_view_b: ViewGeometry) -> FloatArray:
    """Internal parameters z (n,) reproducing ``initial_view_b`` from the model's view B."""
    base = model.view_b
    if (
        initial_view_b.alpha_deg != base.alpha_deg
        or initial_view_b.beta_deg != base.beta_deg
        or initial_view_b.pixel_spacing_mm != base.pixel_spacing_mm
    ):
        raise CalibrationError("initial_view_b must be a corrected version of view_b")
    R = initial_view_b.R_corr @ base.R_corr.T
    t = np.asarray(initial_view_b.t_corr_mm) - R @ np.asarray(base.t_corr_mm)
    z = np.zeros(model.n_params)
    z[:3] = rotvec_from_rotation(R) / model.sigma_rot_rad
    z[3 : 3 + model.n_t] = np.linalg.lstsq(model.T, t, rcond=None)[0]
    if model.intrinsics:
        j = 3 + model.n_t + 3
        z[j] = (initial_view_b.sid_mm - base.sid_mm) / model.sigma_sid_mm
        off = np.subtract(initial_view_b.principal_offset_px, base.principal_offset_px)
        z[j + 1 : j + 3] = off / model.sigma_pp_px
    return z


def refine_with_matches(
    view_a: ViewGeometry,
    view_b: ViewGeometry,
    features_a_px: ArrayLike,
    features_b_px: ArrayLike,
    matched_a_px: ArrayLike,
    matched_b_px: ArrayLike,
    *,
    initial: CalibrationResult | None = None,
    priors: CalibrationPriors | None = CalibrationPriors(),  # noqa: B008 (frozen)
    loss: str = "huber",
    loss_scale_px: float = 2.0,
    match_weight: float = 1.0,
    max_iterations: int = 200,
) -> CalibrationResult:
    """Re-calibrate with the clicked features plus matched centerline pairs (sec. 3.4.2).

    The same objective as :func:`calibrate`, with the (M, 2) matched pairs
    appended to the (K, 2) features (weight ``match_weight`` each), a robust
    Huber loss by default so a few mismatched pairs do not dominate, and
    the priors still centred on the header ``view_b``. ``initial`` (an
    earlier result) is the starting point.
    """
    fa = _checked_points(features_a_px, "features_a_px")
    fb = _checked_points(features_b_px, "features_b_px")
    ma = _checked_points(matched_a_px, "matched_a_px")
    mb = _checked_points(matched_b_px, "matched_b_px")
    if len(ma) != len(mb):
        raise CalibrationError(f"matched pair counts differ: {len(ma)} in A, {len(mb)} in B")
    names = [f"feature {i + 1}" for i in range(len(fa))]
    names += [f"matched pair {i + 1}" for i in range(len(ma))]
    weights = np.concatenate([np.ones(len(fa)), np.full(len(ma), float(match_weight))])
    return calibrate(
        view_a,
        view_b,
        np.concatenate([fa, ma]),
        np.concatenate([fb, mb]),
        method="palm",
        priors=priors,
        weights=weights,
        max_iterations=max_iterations,
        loss=loss,
        loss_scale_px=loss_scale_px,
        initial_view_b=None if initial is None else initial.view_b,
        names=names,
    )


def backprojection_residuals_px(
    view_a: ViewGeometry, view_b: ViewGeometry, points_a_px: ArrayLike, points_b_px: ArrayLike
) -> FloatArray:
    """Eq. (5) per feature: back-projection distances (K, 2) in px in (A, B) for given views."""
    pa = _checked_points(points_a_px, "points_a_px")
    pb = _checked_points(points_b_px, "points_b_px")
    if len(pa) != len(pb):
        raise CalibrationError(f"feature counts differ: {len(pa)} in A, {len(pb)} in B")
    model = _Model(view_a, view_b, pa, pb, np.ones(len(pa)), None, False)
    return model.distances(np.zeros(model.n_params))[0]
