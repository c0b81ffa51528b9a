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
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from recon.geometry import ViewGeometry, rotvec_from_rotation, view_separation_deg
from recon.pose.calibration_model import (
    ANNEAL_ROTATION_BOUND_DEG,
    ANNEAL_TRANSLATION_BOUND_MM,
    CalibrationError,
    CalibrationPriors,
    ResidualModel,
    solve_anneal,
    solve_lm,
    solve_palm,
)
from recon.pose.uncertainty import PosePosterior, log_evidence, pose_posterior

__all__ = [
    "CalibrationError",
    "CalibrationPriors",
    "CalibrationResult",
    "calibrate",
    "calibrate_supported",
    "CORRECTIONS",
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
    correction : which parameters were moved from the header: "full" (all six of
        the rig; :func:`calibrate`), or what :func:`calibrate_supported` chose.
    posterior : the Laplace posterior of the correction (:func:`calibrate_supported`
        only), see :mod:`recon.pose.uncertainty`.
    decision : the model comparison behind ``correction`` (JSON-ready), or None.
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
    correction: str = "full"
    posterior: PosePosterior | None = None
    decision: dict | None = None


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
    model = ResidualModel(view_a, view_b, pa, pb, w, priors, estimate_intrinsics)
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
        sol = solve_palm(model, z0, max_iterations, loss, loss_scale_px)
    elif method == "lm":
        sol = solve_lm(model, z0, max_iterations)
    else:
        sol = solve_anneal(model, z0, max_iterations, loss, loss_scale_px)
    if not sol.converged:
        messages.append(f"{method} did not converge in {max_iterations} iterations")
    if not np.all(np.isfinite(sol.z)):
        raise CalibrationError(f"{method} diverged (non-finite parameters); check the clicks")
    return _result(model, sol.z, method, sol.iterations, sol.converged, w, labels, messages,
                   start)


def _result(
    model: ResidualModel,
    z: FloatArray,
    method: str,
    iterations: int,
    converged: bool,
    w: FloatArray,
    labels: Sequence[str],
    messages: list[str],
    start: float,
) -> CalibrationResult:
    """The :class:`CalibrationResult` of internal parameters z (n,) of ``model``."""
    zero = np.zeros(model.n_params)
    (dist_before, dist_after), (mm_before, mm_after) = model.distances(np.stack([zero, z]))
    far = np.max(dist_after, axis=1) > LARGE_RESIDUAL_PX
    for i in np.flatnonzero(far & (w > 0))[:5]:
        messages.append(
            f"{labels[i]} is still {np.max(dist_after[i]):.1f} px off after calibration; "
            "check the click"
        )
    rotvec, t_mm = model.pose(z)
    rot_deg = float(np.rad2deg(np.linalg.norm(rotvec)))
    if rot_deg > ANNEAL_ROTATION_BOUND_DEG or float(np.linalg.norm(t_mm)) > 2 * (
        ANNEAL_TRANSLATION_BOUND_MM
    ):
        messages.append(
            f"implausible correction: {rot_deg:.1f} deg and {np.linalg.norm(t_mm):.1f} mm "
            "(header errors are expected below a few degrees and centimetres)"
        )
    cal_a, cal_b = model.views(z)
    used = w > 0
    return CalibrationResult(
        view_b=cal_b,
        rotvec=rotvec,
        t_mm=t_mm,
        method=method,
        iterations=iterations,
        elapsed_ms=(time.perf_counter() - start) * 1e3,
        error_before_px=float(np.mean(dist_before[used])),
        error_after_px=float(np.mean(dist_after[used])),
        error_before_mm=float(np.mean(mm_before[used])),
        error_after_mm=float(np.mean(mm_after[used])),
        converged=converged,
        n_features=model.n_features,
        warnings=tuple(messages),
        view_a=cal_a,
        residuals_px=dist_after,
    )


def _initial_parameters(model: ResidualModel, initial_view_b: ViewGeometry) -> FloatArray:
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


# The corrections the decision compares: which of the six rig parameters (rotation
# vector 0-2, translation along B's u, v, d 3-5) move from the header.
CORRECTIONS: dict[str, tuple[int, ...]] = {
    "header": (),
    "translation": (3, 4, 5),
    "full": (0, 1, 2, 3, 4, 5),
}


def _fit_subset(model: ResidualModel, free: NDArray[np.bool_], z0: FloatArray) -> FloatArray:
    """The minimum z (n,) of eq. (5) plus priors with only the ``free`` parameters moving
    (MINPACK LM through scipy; the Jacobian exact by complex step)."""
    from scipy.optimize import least_squares

    def full(x: FloatArray) -> FloatArray:
        z = np.zeros(model.n_params)
        z[free] = x
        return z

    fit = least_squares(
        lambda x: model.residuals(full(x)[None])[0],
        z0[free],
        jac=lambda x: model.residuals_and_jacobian(full(x))[1][:, free],
        method="lm",
        xtol=1e-10,
        ftol=1e-12,
    )
    return full(fit.x)


def calibrate_supported(
    view_a: ViewGeometry,
    view_b: ViewGeometry,
    points_a_px: ArrayLike,
    points_b_px: ArrayLike,
    *,
    method: str = "palm",
    priors: CalibrationPriors = CalibrationPriors(),  # noqa: B008 (frozen)
    names: Sequence[str] | None = None,
    candidates: Sequence[str] = tuple(CORRECTIONS),
) -> CalibrationResult:
    """Move view B from its header only as far as the clicks support.

    1. :func:`calibrate` (all six rig parameters, unit click noise), then the click
       noise sigma is estimated from its residuals (:func:`recon.pose.uncertainty.click_sigma_px`)
       and the full correction is fitted again with the features weighted 1 / sigma^2
       (so the priors weigh against clicks of the measured noise, not of 1 px).
    2. Each candidate correction of :data:`CORRECTIONS` (the header itself, a
       translation of B's rig only, the full rigid correction) is fitted with the same
       noise and priors and scored by its Laplace evidence
       (:func:`recon.pose.uncertainty.log_evidence`): fit minus an Occam term for every
       direction the data must fix. The best-scoring one is returned.

    The result carries ``correction`` (the choice), ``decision`` (each candidate's log
    evidence, residual and pose) and ``posterior``: the full correction's Laplace
    covariance centred on the chosen pose (the uncertainty of the pose does not shrink
    because a simpler correction was chosen).

    Raises :class:`CalibrationError` as :func:`calibrate` does, or for an unknown
    candidate name.
    """
    unknown = [c for c in candidates if c not in CORRECTIONS]
    if unknown or not candidates:
        raise CalibrationError(
            f"unknown correction {unknown or candidates!r} (use some of {tuple(CORRECTIONS)})"
        )
    start = time.perf_counter()
    first = calibrate(view_a, view_b, points_a_px, points_b_px, method=method, priors=priors,
                      names=names)
    pa = _checked_points(points_a_px, "points_a_px")
    pb = _checked_points(points_b_px, "points_b_px")
    unit = ResidualModel(view_a, view_b, pa, pb, np.ones(len(pa)), priors, False)
    sigma = pose_posterior(unit, _initial_parameters(unit, first.view_b)).click_sigma_px
    w = np.full(len(pa), 1.0 / sigma**2)
    full = calibrate(view_a, view_b, pa, pb, method=method, priors=priors, names=names,
                     weights=w, initial_view_b=first.view_b)
    weighted = ResidualModel(view_a, view_b, pa, pb, w, priors, False)
    z_full = _initial_parameters(weighted, full.view_b)
    posterior = pose_posterior(unit, z_full)
    sigma = posterior.click_sigma_px
    w = np.full(len(pa), 1.0 / sigma**2)
    weighted = ResidualModel(view_a, view_b, pa, pb, w, priors, False)
    rows: dict[str, dict] = {}
    fits: dict[str, FloatArray] = {}
    for name in candidates:
        free = np.zeros(unit.n_params, dtype=bool)
        free[list(CORRECTIONS[name])] = True
        if name == "full":
            z = z_full
        elif not free.any():
            z = np.zeros(unit.n_params)
        else:
            z = _fit_subset(weighted, free, z_full * free)
        fits[name] = z
        rotvec, t_mm = unit.pose(z)
        dist = unit.distances(z)[0]
        rows[name] = {
            "log_evidence": log_evidence(unit, z, free, sigma),
            "error_px": float(np.mean(dist)),
            "rotation_deg": float(np.rad2deg(np.linalg.norm(rotvec))),
            "translation_mm": float(np.linalg.norm(t_mm)),
        }
    chosen = max(rows, key=lambda k: rows[k]["log_evidence"])
    z = fits[chosen]
    messages = [m for m in full.warnings if "still" not in m and "implausible" not in m]
    result = _result(unit, z, method, first.iterations + full.iterations, full.converged,
                     np.ones(len(pa)), _labels(names, len(pa)), messages, start)
    centred = PosePosterior(**{**posterior.__dict__, "z_hat": z})
    decision = {
        "rule": "largest Laplace evidence (fit to the clicks minus an Occam term per "
        "direction the clicks must fix), click noise estimated from the residuals",
        "chosen": chosen,
        "click_sigma_px": sigma,
        "candidates": rows,
    }
    return _replace_result(result, correction=chosen, posterior=centred, decision=decision)


def _labels(names: Sequence[str] | None, k: int) -> list[str]:
    return [f"feature {i + 1}" for i in range(k)] if names is None else [str(x) for x in names]


def _replace_result(result: CalibrationResult, **changes: object) -> CalibrationResult:
    from dataclasses import replace

    return replace(result, **changes)


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
    model = ResidualModel(view_a, view_b, pa, pb, np.ones(len(pa)), None, False)
    return model.distances(np.zeros(model.n_params))[0]
