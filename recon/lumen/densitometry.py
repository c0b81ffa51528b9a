"""Densitometric lumen area: the third measurement that fixes an elliptic section.

Each view measures one caliper (support) half-width h_k of the lumen section,
along its intersection line l_k (:func:`recon.lumen.surface.intersection_directions`).
Two calipers cannot fix an ellipse (two semi-axes and an orientation); the
attenuation across the vessel gives the third number, the area.

The chords of an ellipse parallel to one direction have lengths
``L(x) = (2 A / (pi h^2)) sqrt(h^2 - x^2)``, x the offset across and h the
support across (affine image of a circle's chords). So the absorption across a
vessel is exactly the circle template of :mod:`recon.trace.profile_fit` at the caliper
half-width h, scaled by A / (pi h^2): the profile fit's depth b (absorption per
px of chord) already holds the area. For a vessel at angle alpha to the ray,
the ray crosses the tube in the plane through the ray and l_k, whose cut has
area A / sin(alpha) and the same support. With m_k the mm per px at the vessel
(eq. 11) and mu_k the image's absorption per mm of contrast-filled lumen,

    b_k = mu_k * m_k * A / (pi h_mm^2 * sin(alpha_k)),
    fill_k = A / (pi h_mm^2) = rho_k / mu_k,   rho_k = b_k sin(alpha_k) / m_k.

mu_k is not known (contrast concentration, the display mapping); it is
calibrated per view where the lumen is round (fill = 1): the points whose two
calipers agree, a robust straight-line fit of rho_k along the arc (contrast
fades slowly along a vessel). :func:`fill_ratios` returns fill_a, fill_b.

:func:`ellipse_from_calipers` builds the ellipse with both calipers and that
area. Two ellipses do (mirror images about the calipers when the lines are at
right angles); the less eccentric one is taken (an assumption; both have the
same area, so no area figure depends on it).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from recon.geometry import ViewGeometry
from recon.types import Centerline3D

__all__ = [
    "ROUND_TOLERANCE",
    "MAX_AXIS_RATIO",
    "CalipersEllipse",
    "ellipse_from_calipers",
    "fill_ratios",
    "calibrate_attenuation",
    "with_fill_ratios",
    "densitometric_weight",
    "densitometric_area",
    "blend_sections",
    "fill_draws",
    "densitometric_sections",
]

FloatArray = NDArray[np.float64]

#: Calipers within this relative difference count as a round lumen (calibration).
ROUND_TOLERANCE = 0.04
#: Flattest lumen the area is allowed to imply (semi-axis ratio; an assumption about
#: lesions: it sets the smallest area two calipers admit, pi h_max^2 / ratio).
MAX_AXIS_RATIO = 4.0
#: Fewest round points (and share of all points) the calibration needs.
_MIN_ROUND_POINTS = 12
_MIN_ROUND_SHARE = 0.25


@dataclass(frozen=True, eq=False)
class CalipersEllipse:
    """Ellipses (M) in the section planes' (e1, e2) frames, e1 = view A's line.

    m11, m12, m22 : (M,) the shape matrix M (points x with x^T M^-1 x <= 1); the
        support along a unit u is sqrt(u^T M u) and the area pi sqrt(det M).
    area_mm2 : (M,) the area actually used (the requested one clipped to what the
        two calipers admit).
    clipped : (M,) bool, the requested area was outside that range.
    """

    m11: FloatArray
    m12: FloatArray
    m22: FloatArray
    area_mm2: FloatArray
    clipped: NDArray[np.bool_]


def ellipse_from_calipers(h_a_mm: FloatArray, h_b_mm: FloatArray, theta_rad: FloatArray,
                          area_mm2: FloatArray) -> CalipersEllipse:
    """The ellipses (M) with support h_a along e1, h_b along (cos theta, sin theta)
    and area ``area_mm2`` (clipped to the admissible range).

    With M11 = h_a^2 (the support along e1), h_b^2 = c^2 M11 + 2 c s M12 + s^2 M22
    and det M = (A / pi)^2, M12 solves a quadratic with roots
    ``-c h_a^2 / s +- sqrt(h_a^2 h_b^2 / s^2 - (A/pi)^2)``: real up to the area
    pi h_a h_b / |s| of the ellipse inscribed in the calipers' parallelogram. The
    root of the smaller trace (the less eccentric ellipse) is taken. Areas below
    pi max(h)^2 / :data:`MAX_AXIS_RATIO` are raised to it.
    """
    h_a = np.asarray(h_a_mm, dtype=float)
    h_b = np.asarray(h_b_mm, dtype=float)
    theta = np.asarray(theta_rad, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    flip = s < 0  # the line's sign is arbitrary: take s >= 0
    c, s = np.where(flip, -c, c), np.abs(s)
    s = np.maximum(s, 1e-6)
    a_max = np.pi * h_a * h_b / s
    a_min = np.pi * np.maximum(h_a, h_b) ** 2 / MAX_AXIS_RATIO
    a_req = np.asarray(area_mm2, dtype=float)
    area = np.clip(a_req, np.minimum(a_min, a_max), a_max)
    k = (area / np.pi) ** 2
    root = np.sqrt(np.maximum((h_a * h_b / s) ** 2 - k, 0.0))
    m12 = -c * h_a**2 / s + np.where(c >= 0, root, -root)  # maximises c s M12
    m11 = h_a**2
    m22 = (h_b**2 - c**2 * m11 - 2.0 * c * s * m12) / s**2
    return CalipersEllipse(m11=m11, m12=m12, m22=m22, area_mm2=area,
                           clipped=(a_req > a_max * (1 + 1e-9)) | (a_req < a_min * (1 - 1e-9)))


def _robust_line(s: FloatArray, y: FloatArray, iterations: int = 4) -> tuple[float, float]:
    """Intercept and slope of y(s) by least squares, refitted without points more than
    3 robust sd off (a few passes)."""
    keep = np.ones(len(s), dtype=bool)
    coef = np.array([float(np.median(y)), 0.0])
    for _ in range(iterations):
        if np.count_nonzero(keep) < 3:
            break
        coef = np.polynomial.polynomial.polyfit(s[keep], y[keep], 1)
        res = y - (coef[0] + coef[1] * s)
        sd = 1.4826 * float(np.median(np.abs(res[keep]))) + 1e-12
        new = np.abs(res) <= 3.0 * sd
        if np.array_equal(new, keep):
            break
        keep = new
    return float(coef[0]), float(coef[1])


def calibrate_attenuation(s_mm: FloatArray, rho: FloatArray,
                          round_mask: NDArray[np.bool_]) -> FloatArray | None:
    """mu (M,): the straight-line robust fit of rho over the round points, evaluated
    at every s; None when too few points are round or the fit is not positive."""
    n_round = int(np.count_nonzero(round_mask))
    if n_round < max(_MIN_ROUND_POINTS, _MIN_ROUND_SHARE * len(s_mm)):
        return None
    c0, c1 = _robust_line(s_mm[round_mask], rho[round_mask])
    mu = c0 + c1 * s_mm
    if not np.all(mu > 0) or not np.all(np.isfinite(mu)):
        return None
    return mu


def fill_ratios(
    X_world: FloatArray, tangents: FloatArray, s_mm: FloatArray,
    radius_a_mm: FloatArray, radius_b_mm: FloatArray,
    depth_a: FloatArray, depth_b: FloatArray,
    view_a: ViewGeometry, view_b: ViewGeometry,
    usable: NDArray[np.bool_] | None = None,
) -> tuple[FloatArray, FloatArray] | None:
    """Densitometric area over each view's caliper circle, fill_k = A / (pi h_k^2) (M,).

    X_world, tangents, s_mm : (M, ...) the 3D centerline; radius_k_mm : (M,) the
    calipers (eq. 11); depth_k : (M,) the profile fit's depth in view k (absorption
    per px of chord, any units constant along the trace); usable : (M,) bool, points
    whose depths may calibrate (default all). None when a view cannot be calibrated.
    """
    from recon.correspond.triangulation import radius_mm_eq11

    X = np.asarray(X_world, dtype=float)
    T = np.asarray(tangents, dtype=float)
    r_a, r_b = np.asarray(radius_a_mm, dtype=float), np.asarray(radius_b_mm, dtype=float)
    ok = np.ones(len(X), dtype=bool) if usable is None else np.asarray(usable, dtype=bool)
    agree = np.abs(r_a - r_b) <= ROUND_TOLERANCE * 0.5 * (r_a + r_b)
    fills = []
    for depth, view in ((depth_a, view_a), (depth_b, view_b)):
        ray = X - view.source_world
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        sin_alpha = np.linalg.norm(np.cross(ray, T), axis=1)
        mm_per_px = radius_mm_eq11(np.ones(len(X)), X, view)
        rho = np.asarray(depth, dtype=float) * sin_alpha / mm_per_px
        good = ok & np.isfinite(rho) & (rho > 0) & (sin_alpha > 0.3)
        mu = calibrate_attenuation(np.asarray(s_mm, dtype=float), rho, agree & good)
        if mu is None:
            return None
        fills.append(np.where(good, rho / mu, 1.0))
    return fills[0], fills[1]


#: Calipers that differ by less than this (relative) keep the two-caliper section
#: (exact for a circle); the densitometric ellipse takes over fully at
#: DISAGREE_LO + DISAGREE_SPAN.
DISAGREE_LO = 0.04
DISAGREE_SPAN = 0.08
#: The two views' densitometric areas agree within this |log ratio| (full trust) ...
AGREE_LO = 0.12
#: ... and lose all trust this much further apart.
AGREE_SPAN = 0.12


def with_fill_ratios(cl3d: Centerline3D, view_a: ViewGeometry,
                     view_b: ViewGeometry) -> Centerline3D:
    """The pipeline stage: ``cl3d`` with ``fill_a``, ``fill_b`` from its depths
    (:func:`fill_ratios`; points where a view's radius was replaced by the other's
    do not calibrate), or unchanged when it has no depths or a view cannot be
    calibrated."""
    if cl3d.depth_a is None or cl3d.depth_b is None:
        return cl3d
    usable = ~(np.asarray(cl3d.overlap_a) | np.asarray(cl3d.overlap_b))
    fills = fill_ratios(cl3d.X_world, cl3d.tangents, cl3d.s_mm, cl3d.radius_a_mm,
                        cl3d.radius_b_mm, cl3d.depth_a, cl3d.depth_b, view_a, view_b, usable)
    if fills is None:
        return cl3d
    return replace(cl3d, fill_a=fills[0], fill_b=fills[1])


def densitometric_weight(r_a_mm: FloatArray, r_b_mm: FloatArray) -> FloatArray:
    """Weight (M,) in [0, 1] of the densitometric ellipse: 0 where the calipers agree
    within :data:`DISAGREE_LO`, 1 beyond DISAGREE_LO + DISAGREE_SPAN, linear between."""
    e = np.abs(r_a_mm - r_b_mm) / np.maximum(np.maximum(r_a_mm, r_b_mm), 1e-12)
    return np.clip((e - DISAGREE_LO) / DISAGREE_SPAN, 0.0, 1.0)


def densitometric_area(r_a_mm: FloatArray, r_b_mm: FloatArray, fill_a: FloatArray,
                       fill_b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Section area (M,) mm^2, the mean of the two views' estimates pi r_k^2 fill_k, and
    its weight (M,) from their agreement: both views see the same area, whatever its
    shape, so estimates more than :data:`AGREE_LO` apart (|log ratio|) lose trust,
    linearly to none at AGREE_LO + AGREE_SPAN (a wrong caliper or depth in one view:
    an overlap, a touching vessel)."""
    area_a, area_b = np.pi * fill_a * r_a_mm**2, np.pi * fill_b * r_b_mm**2
    gap = np.abs(np.log(np.maximum(area_a, 1e-12) / np.maximum(area_b, 1e-12)))
    weight = np.clip(1.0 - (gap - AGREE_LO) / AGREE_SPAN, 0.0, 1.0)
    return 0.5 * (area_a + area_b), weight


def blend_sections(
    T: FloatArray, l_a: FloatArray, l_b: FloatArray, r_a: FloatArray, r_b: FloatArray,
    major_dir: FloatArray, major_mm: FloatArray, minor_mm: FloatArray, area_mm2: FloatArray,
    weight: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Major axis (M, 3), semi-axes (M,), (M,) of the sections where ``weight`` > 0:
    the shape matrices of the two-caliper ellipse (``major_dir``, ``major_mm``,
    ``minor_mm``) and of :func:`ellipse_from_calipers` with ``area_mm2`` blended by
    ``weight``; elsewhere the inputs unchanged."""
    e1 = l_a
    e2 = np.cross(T, e1)
    e2 /= np.maximum(np.linalg.norm(e2, axis=1, keepdims=True), 1e-300)
    theta = np.arctan2(np.einsum("ij,ij->i", l_b, e2), np.einsum("ij,ij->i", l_b, e1))
    dens = ellipse_from_calipers(r_a, r_b, theta, area_mm2)
    cu, su = np.einsum("ij,ij->i", major_dir, e1), np.einsum("ij,ij->i", major_dir, e2)
    a2, b2 = major_mm**2, minor_mm**2
    p11 = a2 * cu**2 + b2 * su**2
    p12 = (a2 - b2) * cu * su
    p22 = a2 * su**2 + b2 * cu**2
    w = np.clip(weight, 0.0, 1.0)
    m11 = (1 - w) * p11 + w * dens.m11
    m12 = (1 - w) * p12 + w * dens.m12
    m22 = (1 - w) * p22 + w * dens.m22
    half_tr, half_diff = 0.5 * (m11 + m22), np.hypot(0.5 * (m11 - m22), m12)
    lam1, lam2 = half_tr + half_diff, np.maximum(half_tr - half_diff, 0.0)
    psi = 0.5 * np.arctan2(2.0 * m12, m11 - m22)
    new_dir = np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2
    # keep the old axis's sign (the sign is arbitrary; surface.py makes it consistent)
    new_dir *= np.where(np.einsum("ij,ij->i", new_dir, major_dir) < 0, -1.0, 1.0)[:, None]
    use = w > 0
    return (np.where(use[:, None], new_dir, major_dir), np.where(use, np.sqrt(lam1), major_mm),
            np.where(use, np.sqrt(lam2), minor_mm))


def fill_draws(cl3d: Centerline3D, n_samples: int, rng: np.random.Generator) -> FloatArray:
    """Multiplicative draws (n, 2, M) of fill_a, fill_b for the intervals.

    Two parts, each one value per draw along the whole vessel (a calibration error
    is shared by every point): per view, a log-normal factor whose sd is the robust
    scatter of log fill over the points that count as round (where fill is 1 up to
    noise); for both views, a factor uniform in 1 +- |A_a - A_b| / (A_a + A_b), the
    two views' densitometric areas' disagreement at each point.
    """
    fa, fb = np.asarray(cl3d.fill_a, dtype=float), np.asarray(cl3d.fill_b, dtype=float)
    r_a, r_b = np.asarray(cl3d.radius_a_mm), np.asarray(cl3d.radius_b_mm)
    round_pts = densitometric_weight(r_a, r_b) == 0
    sds = []
    for f in (fa, fb):
        logs = np.log(np.maximum(f[round_pts], 1e-6))
        sds.append(1.4826 * float(np.median(np.abs(logs - np.median(logs)))) if logs.size else 0.0)
    area_a, area_b = fa * r_a**2, fb * r_b**2
    gap = np.abs(area_a - area_b) / np.maximum(area_a + area_b, 1e-12)
    m = len(fa)
    shift = rng.standard_normal((n_samples, 2, 1)) * np.array(sds)[None, :, None]
    spread = 1.0 + rng.uniform(-1.0, 1.0, (n_samples, 1, 1)) * gap[None, None, :]
    return np.exp(shift) * np.broadcast_to(spread, (n_samples, 2, m))


def densitometric_sections(
    cl3d: Centerline3D, T: FloatArray, l_a: FloatArray, l_b: FloatArray, r_a: FloatArray,
    r_b: FloatArray, major_dir: FloatArray, major_mm: FloatArray, minor_mm: FloatArray,
    line_weight: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """The two-caliper sections (major axis (M, 3), semi-axes (M,), (M,)) with the
    densitometric ellipse blended in (:func:`blend_sections`) where the calipers
    disagree (:func:`densitometric_weight`), the two views' areas agree
    (:func:`densitometric_area`), neither view's radius was replaced (an overlap)
    and the two lines are far enough from parallel (``line_weight`` (M,), the
    two-caliper builder's own); None when ``cl3d`` has no fill ratios or no point
    qualifies."""
    if cl3d.fill_a is None or cl3d.fill_b is None:
        return None
    w = densitometric_weight(r_a, r_b) * line_weight
    w *= ~(np.asarray(cl3d.overlap_a) | np.asarray(cl3d.overlap_b))
    area, w_agree = densitometric_area(r_a, r_b, np.asarray(cl3d.fill_a),
                                       np.asarray(cl3d.fill_b))
    k = np.flatnonzero(w * w_agree > 0)
    if not k.size:
        return None
    major_dir, major_mm, minor_mm = major_dir.copy(), major_mm.copy(), minor_mm.copy()
    major_dir[k], major_mm[k], minor_mm[k] = blend_sections(
        T[k], l_a[k], l_b[k], r_a[k], r_b[k], major_dir[k], major_mm[k], minor_mm[k],
        area[k], (w * w_agree)[k])
    return major_dir, major_mm, minor_mm
