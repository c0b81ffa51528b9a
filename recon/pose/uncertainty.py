"""How sure the calibrated pose is: the Laplace posterior of view B's correction.

Calibration (:mod:`recon.pose.calibration`) minimises eq. (5) plus the priors. Near
its minimum the cost is quadratic in the parameters, so the posterior of view
B's correction is Gaussian with the Gauss-Newton covariance (the Laplace
approximation)

    Cov(z) = (J^T J / sigma^2 + P)^-1,

with J the (4K, n) Jacobian of the back-projection residuals of eq. (5) with
respect to the internal parameters z (units of the prior sigmas, so the prior
precision P is the identity; without priors P = 0 and the baseline length is
held), and sigma the click noise in px.

The click noise is estimated from the residuals. The 4K residuals of K
features carry about K independent numbers (each feature's triangulation
absorbs three of its four coordinates: what is left is its distance across
the epipolar line), and the fit uses p_eff = trace(H (H + P)^-1) of them
(H = J^T J / sigma^2), so

    sigma^2 = (nu0 sigma0^2 + RSS) / (nu0 + K - p_eff)

(a scaled inverse-chi^2 prior on sigma^2 with nu0 = :data:`CLICK_SIGMA_PRIOR_DOF`
pseudo-residuals of sigma0 = :data:`CLICK_SIGMA_PRIOR_PX`; with 3-6 clicks the
residuals alone cannot tell the noise, the assumption is stated here), solved by
fixed-point iteration because p_eff depends on sigma.

:func:`observability` turns the posterior into words: for six named directions
of B's rig (rotation about / translation along the line between the two
sources, the axis perpendicular to both beams, and the axis across the
baseline in the beams' plane) the posterior sd against the prior sd says
whether the images fixed it (ratio below :data:`FIXED_RATIO`), fixed it partly,
or left it to the header (ratio above :data:`HEADER_RATIO`).

:func:`log_evidence` is the Laplace evidence of a correction that frees a
subset of the parameters, the basis of the decision "move from the header only
as far as the data support" (:func:`recon.pose.calibration.calibrate_supported`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from recon.geometry import ViewGeometry
from recon.lumen.measure import Measurements
from recon.pose.calibration_model import ResidualModel
from recon.types import Centerline3D, arclength

FloatArray = NDArray[np.float64]

__all__ = [
    "CLICK_SIGMA_PRIOR_PX",
    "CLICK_SIGMA_PRIOR_DOF",
    "PosePosterior",
    "pose_posterior",
    "click_sigma_px",
    "log_evidence",
    "observability",
    "named_axes",
    "MeasurementIntervals",
    "RadiusErrorModel",
    "measurement_intervals",
    "radius_error_model",
]

CLICK_SIGMA_PRIOR_PX = 1.0  # assumed click noise per coordinate before the residuals speak
CLICK_SIGMA_PRIOR_DOF = 3.0  # weight of that assumption, in residuals
FIXED_RATIO = 0.5  # posterior sd below this fraction of the prior sd: fixed by the images
HEADER_RATIO = 0.9  # above this fraction: the header's value stands
_SIGMA_ITERATIONS = 20

DIRECTION_NAMES = (
    "rotation about the baseline",
    "rotation about the normal to both beams",
    "rotation about the cross-baseline axis",
    "translation along the baseline",
    "translation along the normal to both beams",
    "translation along the cross-baseline axis",
)
_DIRECTION_KEYS = (
    "rotation_baseline",
    "rotation_normal",
    "rotation_cross",
    "translation_baseline",
    "translation_normal",
    "translation_cross",
)


@dataclass(frozen=True, eq=False)
class PosePosterior:
    """Gaussian (Laplace) posterior of view B's correction.

    Attributes
    ----------
    z_hat : (n,) internal parameters at the minimum (units of the prior sigmas).
    cov_z : (n, n) posterior covariance of z.
    pose_map : (6, n) linear map from z to (rotation vector rad, translation mm).
    cov_pose : (6, 6) posterior covariance of (rotvec rad, t mm), world frame.
    prior_cov_pose : (6, 6) prior covariance of the same (inf on the diagonal for a
        parameter without a prior; 0 where it is held, e.g. the baseline without priors).
    click_sigma_px : estimated click noise per coordinate, px.
    residual_dof : K - p_eff, the residuals' degrees of freedom left after the fit.
    n_features : K.
    axes : (3, 3) rows: the named directions (baseline, normal to both beams,
        cross-baseline), world frame, orthonormal.
    """

    z_hat: FloatArray
    cov_z: FloatArray
    pose_map: FloatArray
    cov_pose: FloatArray
    prior_cov_pose: FloatArray
    click_sigma_px: float
    residual_dof: float
    n_features: int
    axes: FloatArray

    def sample_z(self, rng: np.random.Generator, n: int) -> FloatArray:
        """(n, n_params) draws of z from the posterior."""
        L = _psd_sqrt(self.cov_z)
        return self.z_hat[None, :] + rng.standard_normal((n, len(self.z_hat))) @ L.T

    def named_sd(self) -> tuple[FloatArray, FloatArray]:
        """Posterior and prior sd (6,) along the named directions: 3 rotations (deg), 3
        translations (mm), in the order of :data:`DIRECTION_NAMES`."""
        E = np.zeros((6, 6))
        E[:3, :3] = self.axes
        E[3:, 3:] = self.axes
        post = np.sqrt(np.maximum(np.diag(E @ self.cov_pose @ E.T), 0.0))
        with np.errstate(invalid="ignore"):
            prior = np.sqrt(np.maximum(np.diag(E @ self.prior_cov_pose @ E.T), 0.0))
        scale = np.array([np.rad2deg(1.0)] * 3 + [1.0] * 3)
        return post * scale, prior * scale


def _psd_sqrt(C: FloatArray) -> FloatArray:
    """A square root L (L L^T = C) of a symmetric positive semi-definite matrix."""
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    return V * np.sqrt(np.maximum(w, 0.0))[None, :]


def named_axes(view_a: ViewGeometry, view_b: ViewGeometry) -> FloatArray:
    """(3, 3) orthonormal rows: the baseline (A's source to B's), the normal to both
    central rays, and the axis across the baseline in the plane of the beams."""
    e1 = view_b.source_world - view_a.source_world
    e1 = e1 / np.linalg.norm(e1)
    n = np.cross(view_a.R_view_from_world[2], view_b.R_view_from_world[2])
    n = n - (n @ e1) * e1
    if np.linalg.norm(n) < 1e-9:  # parallel beams: any normal to the baseline
        n = np.cross(e1, [1.0, 0.0, 0.0] if abs(e1[0]) < 0.9 else [0.0, 1.0, 0.0])
    e2 = n / np.linalg.norm(n)
    return np.stack([e1, e2, np.cross(e1, e2)])


def _image_jacobian(model: ResidualModel, z: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Weighted image residuals (4K,) and their Jacobian (4K, n) at z (no prior rows)."""
    r, J = model.residuals_and_jacobian(np.asarray(z, dtype=float))
    m = 4 * model.n_features
    return r[:m], J[:m]


def click_sigma_px(
    r_img: FloatArray, J_img: FloatArray, n_features: int, has_priors: bool
) -> tuple[float, float]:
    """Click noise sigma (px) and the residual dof K - p_eff (module docstring).

    ``r_img`` (4K,) and ``J_img`` (4K, n) are in px (unit feature weights).
    """
    rss = float(r_img @ r_img)
    JtJ = J_img.T @ J_img
    n = JtJ.shape[0]
    P = np.eye(n) if has_priors else np.zeros((n, n))
    s2 = CLICK_SIGMA_PRIOR_PX**2
    dof = float(n_features)
    for _ in range(_SIGMA_ITERATIONS):
        H = JtJ / s2
        p_eff = float(np.trace(np.linalg.pinv(H + P) @ H))
        dof = max(n_features - p_eff, 0.0)
        new = (CLICK_SIGMA_PRIOR_DOF * CLICK_SIGMA_PRIOR_PX**2 + rss) / (
            CLICK_SIGMA_PRIOR_DOF + dof
        )
        if abs(new - s2) < 1e-10 * s2:
            s2 = new
            break
        s2 = new
    return float(np.sqrt(s2)), dof


def _pose_map(model: ResidualModel) -> FloatArray:
    M = np.zeros((6, model.n_params))
    M[:3, :3] = model.sigma_rot_rad * np.eye(3)
    M[3:, 3 : 3 + model.n_t] = model.T
    return M


def pose_posterior(
    model: ResidualModel, z_hat: FloatArray, sigma_px: float | None = None
) -> PosePosterior:
    """The Laplace posterior of B's correction at the minimum ``z_hat`` (n,).

    ``model`` carries unit feature weights (residuals in px); ``sigma_px`` None
    estimates the click noise from the residuals (:func:`click_sigma_px`).
    """
    z_hat = np.asarray(z_hat, dtype=float)
    r, J = _image_jacobian(model, z_hat)
    est, dof = click_sigma_px(r, J, model.n_features, model.has_priors)
    sigma = est if sigma_px is None else float(sigma_px)
    n = model.n_params
    P = np.eye(n) if model.has_priors else np.zeros((n, n))
    cov_z = np.linalg.pinv(J.T @ J / sigma**2 + P, hermitian=True)
    M = _pose_map(model)
    if model.has_priors:
        prior = M @ M.T
    else:  # no prior: infinite along free directions, zero along the held baseline
        prior = np.diag([np.inf] * 3 + [0.0] * 3)
        prior[3:, 3:] = np.where(M[3:] @ M[3:].T > 0, np.inf, 0.0)
    return PosePosterior(
        z_hat=z_hat,
        cov_z=cov_z,
        pose_map=M,
        cov_pose=M @ cov_z @ M.T,
        prior_cov_pose=prior,
        click_sigma_px=sigma,
        residual_dof=dof,
        n_features=model.n_features,
        axes=named_axes(*model.views(z_hat)),
    )


def log_evidence(
    model: ResidualModel, z_hat: FloatArray, free: NDArray[np.bool_], sigma_px: float
) -> float:
    """Laplace log evidence (up to a constant shared by all subsets) of a correction
    freeing the parameters ``free`` (n,) bool, at its minimum ``z_hat`` (zero off ``free``).

    log Z = -1/2 (RSS / sigma^2 + |z|^2) - 1/2 log det(I + J_f^T J_f / sigma^2),
    J_f the image Jacobian's free columns; prior N(0, I) on the free z.
    """
    r, J = _image_jacobian(model, z_hat)
    zf = np.asarray(z_hat)[free]
    chi2 = float(r @ r) / sigma_px**2 + float(zf @ zf)
    Jf = J[:, free] / sigma_px
    _, logdet = np.linalg.slogdet(np.eye(int(np.count_nonzero(free))) + Jf.T @ Jf)
    return -0.5 * chi2 - 0.5 * float(logdet)


def observability(posterior: PosePosterior) -> dict:
    """Which directions of B's rig the images fixed and which rest on the header.

    Returns a JSON-ready dict: ``summary`` (one plain sentence), ``click_sigma_px``,
    and ``directions``: per named direction its posterior and prior sd (deg or mm),
    their ratio and a status "images" (ratio < FIXED_RATIO), "partly" or "header"
    (ratio > HEADER_RATIO), "held" (not estimated: held at the header's value).
    """
    post, prior = posterior.named_sd()
    rows = {}
    groups: dict[str, list[str]] = {"images": [], "partly": [], "header": [], "held": []}
    for key, name, p, q in zip(_DIRECTION_KEYS, DIRECTION_NAMES, post, prior, strict=True):
        unit = "deg" if key.startswith("rotation") else "mm"
        if q == 0.0 or not np.isfinite(p):
            status, ratio = "held", None
        elif not np.isfinite(q):
            ratio = 0.0
            status = "images"
        else:
            ratio = float(p / q)
            status = (
                "images" if ratio < FIXED_RATIO else "header" if ratio > HEADER_RATIO else "partly"
            )
        rows[key] = {
            "name": name,
            "unit": unit,
            "posterior_sd": float(p) if np.isfinite(p) else None,
            "prior_sd": float(q) if np.isfinite(q) else None,
            "ratio": ratio,
            "status": status,
        }
        groups[status].append(f"{name} (sd {p:.2g} {unit})" if status != "held" else name)
    parts = []
    if groups["images"]:
        parts.append("the images fixed the " + ", ".join(groups["images"]))
    if groups["partly"]:
        parts.append("they fixed partly the " + ", ".join(groups["partly"]))
    if groups["header"]:
        verb = "rests" if len(groups["header"]) == 1 else "rest"
        parts.append("the " + ", ".join(groups["header"]) + f" {verb} on the header")
    if groups["held"]:
        verb = "is" if len(groups["held"]) == 1 else "are"
        parts.append("the " + ", ".join(groups["held"]) + f" {verb} held at the header's value")
    summary = "; ".join(parts)
    summary = summary[:1].upper() + summary[1:] + (
        f" (click noise {posterior.click_sigma_px:.2f} px from {posterior.n_features} marks). "
        "The translation along the baseline sets the depth scale: "
        + (
            "it rests on the header's SOD."
            if rows["translation_baseline"]["status"] in ("header", "held")
            else "the marks constrain it only through the priors' coupling."
            if rows["translation_baseline"]["status"] == "partly"
            else "the marks fixed it."
        )
    )
    return {
        "summary": summary,
        "click_sigma_px": posterior.click_sigma_px,
        "residual_dof": posterior.residual_dof,
        "directions": rows,
    }


# ------------------------------------------------------- measurement intervals
CI_SAMPLES = 32  # posterior draws per reconstruction (sd to about 13 %)
CI_Z = 1.959964  # two-sided 95 % normal quantile
_RADIUS_CORRELATION_MAX_MM = 5.0
# sd (px) of the 2D radius error the two views share (the profile model's own bias at a
# narrowing, the blur model): an assumption, set from `bench centerline`'s radius mean
# absolute error of 0.14 px against the phantom's truth (docs/benchmarks.md); the two
# views' disagreement cannot show it
COMMON_RADIUS_SD_PX = 0.15
#: The stretch (mm of 3D arc length) at each end over which a trace's px are turned
#: into mm of the segment's length (:func:`_end_draws`).
END_STRETCH_MM = 2.0
_RADIUS_LOCAL_WINDOW_MM = 5.0
#: Figures that are places along the centerline (their intervals stay on the segment).
_SITE_KEYS = ("mld_s_mm", "lesion_start_s_mm", "lesion_end_s_mm")


@dataclass(frozen=True, eq=False)
class RadiusErrorModel:
    """Each view's relative 2D radius error along the 3D centerline, as a Gaussian field.

    The two views measure one lumen from two sides; for a circular section their
    radii (eq. 11) are equal, so d(s) = ln(r_a / r_b) is the difference of the two
    fits' relative errors. Each view's error is modelled as e_v(s) = g_v + h_v(s):
    an offset g_v of sd ``offset_sd`` (from the mean of d: one draw of g_a - g_b)
    plus a stationary-shaped field of local sd ``local_sd`` (M,) (the running rms of
    d - mean(d) over 5 mm, divided by sqrt 2) with a Gaussian correlation of length
    ``correlation_mm`` (where d's autocorrelation falls to 1/2). An eccentric lumen
    also makes d non-zero: the model then over-states the error (wider intervals).

    Attributes
    ----------
    offset_sd : sd of the per-view offset of ln r.
    local_sd : (M,) sd of the local part of ln r per view.
    correlation_mm : correlation length along the vessel, mm.
    """

    offset_sd: float
    local_sd: FloatArray
    correlation_mm: float

    def field(self, rng: np.random.Generator, s_mm: FloatArray, shape: tuple[int, ...]
              ) -> FloatArray:
        """(*shape, M) draws of a unit-sd Gaussian field along s_mm (M,) with the model's
        correlation length."""
        from scipy.ndimage import gaussian_filter1d

        m = len(s_mm)
        step = float(np.median(np.diff(s_mm))) if m > 1 else 1.0
        width = max(self.correlation_mm / step / np.sqrt(2.0), 1e-3)  # kernel sd in samples
        field = gaussian_filter1d(rng.standard_normal((*shape, m)), width, axis=-1,
                                  mode="reflect")
        return field / np.maximum(np.std(field, axis=-1, keepdims=True), 1e-12)

    def sample(self, rng: np.random.Generator, s_mm: FloatArray, n: int) -> FloatArray:
        """(n, 2, M) draws of ln-radius errors of views A and B at arc lengths s_mm (M,)."""
        field = self.field(rng, s_mm, (n, 2))
        offset = self.offset_sd * rng.standard_normal((n, 2, 1))
        return offset + self.local_sd[None, None, :] * field


def radius_error_model(
    s_mm: FloatArray, radius_a_mm: FloatArray, radius_b_mm: FloatArray
) -> RadiusErrorModel:
    """:class:`RadiusErrorModel` from the two views' radii (M,) along the centerline."""
    from scipy.ndimage import uniform_filter1d

    d = np.log(np.maximum(radius_a_mm, 1e-6) / np.maximum(radius_b_mm, 1e-6))
    m = len(d)
    step = float(np.median(np.diff(s_mm))) if m > 1 else 1.0
    centred = d - np.mean(d)
    window = max(int(round(_RADIUS_LOCAL_WINDOW_MM / step)) | 1, 1)
    local = np.sqrt(uniform_filter1d(centred**2, window, mode="nearest") / 2.0)
    var = float(np.mean(centred**2))
    corr = _RADIUS_CORRELATION_MAX_MM
    if var > 0 and m > 2:
        ac = np.correlate(centred, centred, mode="full")[m - 1 :] / (var * np.arange(m, 0, -1))
        below = np.flatnonzero(ac[: max(m // 2, 2)] < 0.5)
        if below.size:
            corr = float(np.clip(below[0] * step, step, _RADIUS_CORRELATION_MAX_MM))
    return RadiusErrorModel(
        offset_sd=float(abs(np.mean(d)) / np.sqrt(2.0)),
        local_sd=local,
        correlation_mm=corr,
    )


@dataclass(frozen=True, eq=False)
class MeasurementIntervals:
    """95 % intervals of the 3D QCA figures and of the radius along the centerline.

    Attributes
    ----------
    ci95 : {measurement name: (lo, hi)} for every number of
        :meth:`recon.lumen.measure.Measurements.to_dict` (``has_lesion`` excepted).
    radius_lo_mm, radius_hi_mm : (M,) 95 % interval of the equivalent radius at
        each centerline point (same arc-length fraction in every draw).
    n_samples : posterior draws behind them.
    lesion_found_fraction : share of the draws that found a lesion.
    radius_error : the 2D radius error model used (JSON-ready figures).
    flagged_mm : per view (A, B), the [start, end] mm stretches drawn under the
        "that view is wrong there" hypothesis too.
    profiles : each draw's lumen profile as measured (:class:`recon.lumen.measure.LumenProfile`;
        the FFR's interval, :mod:`recon.lumen.ffr`, is computed over them).
    """

    ci95: dict[str, tuple[float, float]]
    radius_lo_mm: FloatArray
    radius_hi_mm: FloatArray
    n_samples: int
    lesion_found_fraction: float
    radius_error: dict
    flagged_mm: list = field(default_factory=list)
    profiles: tuple = ()


def measurement_intervals(
    view_a: ViewGeometry,
    view_b_header: ViewGeometry,
    posterior: PosePosterior,
    centerline: Centerline3D,
    measurements: Measurements,
    *,
    n_samples: int = CI_SAMPLES,
    seed: int = 0,
    flagged_a: NDArray[np.bool_] | None = None,
    flagged_b: NDArray[np.bool_] | None = None,
    measure_from_s_mm: float | None = None,
    ostium_end_s_mm: float | None = None,
) -> MeasurementIntervals:
    """95 % intervals by sampling the pose posterior and the 2D radius error.

    Each draw takes view B's correction from ``posterior`` (the full Laplace
    covariance, so the baseline scale's prior counts too) and re-triangulates the
    reconstructed centerline's own projections (M points, the correspondence held:
    to first order a pose change moves the smooth curve as it moves its points),
    rescales each view's radius by eq. (11)'s depth ratio, by the draw of
    :func:`radius_error_model` (estimated on ``centerline``) and by a draw of the
    error both views' fits share (:data:`COMMON_RADIUS_SD_PX` relative to each view's
    radius in px, one field for both views: no disagreement shows it), builds the elliptic
    sections (no surface) and measures (:func:`recon.lumen.measure.lumen_profile`,
    :func:`recon.lumen.measure.measure_lumen`). The interval of each figure is its value
    in ``measurements`` +- 1.96 sample sd (centred on the reported figure: the draws'
    minima are biased low), lengths and diameters clipped at 0.

    ``flagged_a`` / ``flagged_b`` (M,) bool: where the pipeline has evidence that
    that view's trace is wrong (:mod:`recon.correspond.consistency`: the 3D centerline is off
    the view's vessel, or its arc length disagrees with the trace: a detour, a trace
    onto a neighbour). There the draws are a mixture of two hypotheses, each with
    probability 1/2 per draw and view: the measurement as made, or the flagged view
    wrong over each flagged stretch, i.e. its radius replaced by the other view's
    and the stretch's 3D path by the straight chord between the stretch's ends (a
    detour removed). The interval then spans both readings where, and only where,
    the evidence is. Where the sections use the densitometric area
    (:mod:`recon.lumen.densitometry`), its fill ratios are drawn too
    (:func:`recon.lumen.densitometry.fill_draws`): the calibration's scatter and the two
    views' disagreement on the area. Where the calipers agree the section is taken
    to be round (an assumption: an ellipse at equal angles to both lines has equal
    calipers too, and only the densitometric area, not used there, would tell).
    Each flagged stretch also loses the local radius model's
    averaging (the disagreement there is evidence, not noise).

    The segment length's draws also carry where its ends were clicked
    (:func:`_end_draws`): the reported curve's own arc length is otherwise held.

    ``measure_from_s_mm``: measure each draw, as ``measurements`` were measured, only
    from this arc length of ``centerline`` on (a branch's QCA from its carina on,
    :mod:`recon.tree`); the radius intervals still cover every point.
    ``ostium_end_s_mm``: the branch's ostium zone ends there (as ``measurements`` were
    measured, :func:`recon.lumen.measure.lumen_profile`).
    """
    from recon.correspond.triangulation import radius_mm_eq11
    from recon.geometry import triangulate
    from recon.lumen.densitometry import fill_draws
    from recon.lumen.measure import lumen_profile, measure_lumen
    from recon.lumen.sections import section_areas

    rng = np.random.default_rng(seed)
    X0, s0 = centerline.X_world, centerline.s_mm
    pose = posterior.pose_map @ posterior.z_hat
    view_b0 = view_b_header.with_correction(pose[:3], pose[3:])
    pa, pb = view_a.project(X0), view_b0.project(X0)
    ones = np.ones(len(X0))
    fa0, fb0 = radius_mm_eq11(ones, X0, view_a), radius_mm_eq11(ones, X0, view_b0)
    err_model = radius_error_model(s0, centerline.radius_a_mm, centerline.radius_b_mm)
    if centerline.fit_radius_a_mm is not None and centerline.fit_radius_b_mm is not None:
        # Where one view's radius stood in for the other's, the two agree by construction
        # and the radius rests on one view: the local error there is the one the views'
        # own fits showed.
        fitted = radius_error_model(s0, centerline.fit_radius_a_mm,
                                    centerline.fit_radius_b_mm)
        stood_in = centerline.overlap_a | centerline.overlap_b
        err_model = replace(err_model, local_sd=np.where(
            stood_in, np.maximum(err_model.local_sd, fitted.local_sd), err_model.local_sd))
    errors = err_model.sample(rng, s0, n_samples)  # (n, 2, M)
    # the part of the 2D fits' error both views share (invisible in their disagreement):
    # COMMON_RADIUS_SD_PX per view, relative to each view's radius in px
    radius_px = np.stack([centerline.radius_a_mm / fa0, centerline.radius_b_mm / fb0])
    common = err_model.field(rng, s0, (n_samples, 1))  # (n, 1, M), one draw for both views
    errors = errors + common * (COMMON_RADIUS_SD_PX / np.maximum(radius_px, 0.5))[None]
    zs = posterior.sample_z(rng, n_samples)
    flags = [_flag_runs(f, len(s0)) for f in (flagged_a, flagged_b)]
    coins = rng.random((n_samples, 2)) < 0.5
    # the densitometric area's error (its own stream: the other draws do not change)
    dens = None
    if centerline.fill_a is not None and centerline.fill_b is not None:
        dens = fill_draws(centerline, n_samples, np.random.default_rng([seed, 14]))
    draws, views_b = [], []
    for k in range(n_samples):
        pose = posterior.pose_map @ zs[k]
        view_b = view_b_header.with_correction(pose[:3], pose[3:])
        X = triangulate(pa, pb, view_a, view_b)
        r_a, r_b = centerline.radius_a_mm, centerline.radius_b_mm
        for v in (0, 1):
            if coins[k, v] and flags[v]:
                X, r_a, r_b = _flagged_view_wrong(X, r_a, r_b, flags[v], v)
        tangents = np.gradient(X, axis=0)
        tangents /= np.maximum(np.linalg.norm(tangents, axis=1, keepdims=True), 1e-12)
        cl = replace(
            centerline,
            X_world=X,
            s_mm=arclength(X),
            tangents=tangents,
            radius_a_mm=r_a * radius_mm_eq11(ones, X, view_a) / fa0 * np.exp(errors[k, 0]),
            radius_b_mm=r_b * radius_mm_eq11(ones, X, view_b) / fb0 * np.exp(errors[k, 1]),
        )
        if dens is not None:
            cl = replace(cl, fill_a=centerline.fill_a * dens[k, 0],
                         fill_b=centerline.fill_b * dens[k, 1])
        draws.append(cl)
        views_b.append(view_b)
    # every draw's sections, and the reported centerline's last, as one stack of rows
    areas = section_areas([*draws, centerline], view_a, [*views_b, view_b0])
    values: dict[str, list[float]] = {}
    found = 0
    keep = (np.ones(len(s0), dtype=bool) if measure_from_s_mm is None
            else s0 >= measure_from_s_mm)
    profiles = []
    for cl, area in zip(draws, areas, strict=False):
        s_kept = cl.s_mm[keep] - cl.s_mm[keep][0] + s0[keep][0]  # arc lengths as reported
        profiles.append(lumen_profile(s_kept, area[keep], ostium_end_s_mm=ostium_end_s_mm))
        m = measure_lumen(profiles[-1])
        found += m.has_lesion
        for key, v in m.to_dict().items():
            if key != "has_lesion":
                values.setdefault(key, []).append(float(v))
    if "segment_length_mm" in values:
        values["segment_length_mm"] = list(np.asarray(values["segment_length_mm"]) + _end_draws(
            rng, X0, s0, (pa, pb), posterior.click_sigma_px, n_samples,
            both_ends=measure_from_s_mm is None))
    radii = np.sqrt(areas[:-1] / np.pi)
    nominal = measurements.to_dict()
    ci = {}
    for key, v in values.items():
        sd = float(np.std(v, ddof=1))
        lo, hi = nominal[key] - CI_Z * sd, nominal[key] + CI_Z * sd
        if not key.endswith("_pct"):
            lo = max(lo, 0.0)
        if key in _SITE_KEYS:  # a place on the measured stretch stays on it
            lo, hi = max(lo, float(s0[keep][0])), min(hi, float(s0[keep][-1]))
        ci[key] = (float(lo), float(hi))
    r0 = np.sqrt(areas[-1] / np.pi)
    r_sd = np.std(radii, axis=0, ddof=1)
    return MeasurementIntervals(
        ci95=ci,
        radius_lo_mm=np.maximum(r0 - CI_Z * r_sd, 0.0),
        radius_hi_mm=r0 + CI_Z * r_sd,
        n_samples=n_samples,
        lesion_found_fraction=found / n_samples,
        radius_error={
            "offset_sd_rel": err_model.offset_sd,
            "local_sd_rel_median": float(np.median(err_model.local_sd)),
            "correlation_mm": err_model.correlation_mm,
            "common_sd_px": COMMON_RADIUS_SD_PX,
        },
        flagged_mm=[[[float(s0[i]), float(s0[j - 1])] for i, j in f] for f in flags],
        profiles=tuple(profiles),
    )


def _end_draws(rng: np.random.Generator, X: FloatArray, s_mm: FloatArray,
               projected: tuple[FloatArray, FloatArray], sigma_px: float, n: int,
               both_ends: bool = True) -> FloatArray:
    """(n,) draws of the segment length's change (mm) from where its ends were clicked.

    Each view's trace ends at a click, and a click's error along the vessel
    (``sigma_px``, the click noise estimated from the residuals) moves that end along
    it. Triangulation splits the two views' disagreement, so an end moves in 3D by the
    mean of the two views' shifts, each times that view's mm of 3D arc length per px
    of trace at the end (over its last :data:`END_STRETCH_MM`; foreshortening makes it
    larger). ``both_ends`` False: only the distal end was clicked (a branch measured
    from its carina)."""
    total = np.zeros(n)
    for end in ((0, -1) if both_ends else (-1,)):
        near = (s_mm <= s_mm[0] + END_STRETCH_MM) if end == 0 else \
            (s_mm >= s_mm[-1] - END_STRETCH_MM)
        idx = np.flatnonzero(near)
        if len(idx) < 2:
            continue
        s3 = float(s_mm[idx[-1]] - s_mm[idx[0]])
        per_px = [s3 / max(float(arclength(p[idx])[-1]), 1e-6) for p in projected]
        shifts = rng.normal(0.0, sigma_px, (n, 2)) * np.asarray(per_px)[None, :]
        total += shifts.mean(axis=1) * (1.0 if end == -1 else -1.0)
    return total


def _flag_runs(flagged: NDArray[np.bool_] | None, m: int) -> list[tuple[int, int]]:
    """Runs [i, j) of True in a (m,) bool mask (none for None)."""
    if flagged is None:
        return []
    f = np.asarray(flagged, dtype=bool)
    if f.shape != (m,):
        raise ValueError(f"flagged mask must be ({m},), got {f.shape}")
    edges = np.diff(np.concatenate([[0], f.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(),
                    strict=True))


def _flagged_view_wrong(
    X: FloatArray, r_a: FloatArray, r_b: FloatArray, runs: list[tuple[int, int]], view: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The hypothesis "view ``view`` (0 = A, 1 = B) is wrong over ``runs``": its radius
    there replaced by the other view's, each run's points (M, 3) moved onto the chord
    between the run's neighbours (a detour removed), at the same fractions of the
    run's arc length."""
    X, r_a, r_b = X.copy(), r_a.copy(), r_b.copy()
    m = len(X)
    for i, j in runs:
        if view == 0:
            r_a[i:j] = r_b[i:j]
        else:
            r_b[i:j] = r_a[i:j]
        lo, hi = max(i - 1, 0), min(j, m - 1)
        if hi - lo < 2:
            continue
        seg = np.linalg.norm(np.diff(X[lo : hi + 1], axis=0), axis=1)
        t = np.concatenate([[0.0], np.cumsum(seg)]) / max(float(np.sum(seg)), 1e-12)
        X[lo : hi + 1] = X[lo] + t[:, None] * (X[hi] - X[lo])[None, :]
    return X, r_a, r_b
