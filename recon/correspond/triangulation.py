"""Matched pairs -> smooth 3D centerline with radii; Table-3 error metrics.

Steps of :func:`build_centerline_3d`:

1. triangulate the matched pixels (eqs. 2-3, ``recon.geometry.triangulate``);
2. fit a 3D smoothing spline X(t) (``scipy.interpolate.make_smoothing_spline``,
   a fixed bandwidth ``SMOOTHING_MM`` along the vessel) against the chord
   length t of the raw points, as the paper smooths its skeleton (fig. 10a);
3. resample X at uniform arc length ``spacing_mm``; unit tangents from X'(t);
4. radii: the 2D radius of each view at the matched point, scaled back to
   the vessel by eq. (11): r_mm = r_px * pixel_size * |X - S| / |D - S|,
   D the detector point of X's projection and S the source, which is the
   paper's sqrt(x^2 + y^2 + z^2) / sqrt(u^2 + v^2 + SID^2);
5. overlaps: where one view's profile fit is not trusted (its 2D reliability
   is below ``OVERLAP_RELIABILITY``: another vessel overlaps or touches it
   there, which widens the fitted lumen, or beside a touching neighbour
   makes it collapse) and the other view's is, and the untrusted radius is
   the larger or below ``_COLLAPSED`` times the other, the trusted view's
   radius stands in for both ellipse axes (a circular lumen is the best
   guess when one view cannot see the width). The stretches are widened by
   ``OVERLAP_MARGIN_MM`` and returned as ``overlap_a``/``overlap_b``; the report lists them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import make_smoothing_spline
from scipy.ndimage import binary_dilation

from recon.errors import CoronaryError
from recon.geometry import ViewGeometry, ray_distance_mm, triangulate
from recon.types import Centerline3D, Matching, arclength

__all__ = [
    "TriangulationError",
    "build_centerline_3d",
    "epipolar_weights",
    "radius_mm_eq11",
    "point_polyline_distance",
    "segment_feet_2d",
    "table3_metrics",
]

FloatArray = NDArray[np.float64]

#: A 2D profile fit with a lower reliability is not trusted for the radius.
OVERLAP_RELIABILITY = 0.5
#: Each untrusted stretch is widened by this much on both sides (mm of 3D arc).
OVERLAP_MARGIN_MM = 1.0


class TriangulationError(CoronaryError):
    """The matched pairs cannot make a 3D centerline; the message says why."""


def _pixel_size_mm(view: ViewGeometry) -> float:
    sr, sc = view.pixel_spacing_mm
    return float(np.sqrt(sr * sc))


def radius_mm_eq11(radius_px: ArrayLike, X_world: ArrayLike, view: ViewGeometry) -> FloatArray:
    """Eq. (11): projected radius (N,) in px -> radius (N,) in mm at the vessel.

    r_mm = r_px * pixel_size * |X - S| / |D - S|, with S the source and D the
    detector point where X projects (the source-to-detector distance of that
    pixel, sqrt(u^2 + v^2 + SID^2)).

    Parameters
    ----------
    radius_px : (N,) radius in pixels; X_world : (N, 3) points in mm.
    """
    X = np.asarray(X_world, dtype=float).reshape(-1, 3)
    r = np.asarray(radius_px, dtype=float).reshape(-1)
    S = view.source_world
    D = view.detector_point_world(view.project(X))
    ratio = np.linalg.norm(X - S, axis=1) / np.linalg.norm(D - S, axis=1)  # eq. (11)
    return r * _pixel_size_mm(view) * ratio


def _presmoothed(X: FloatArray, width: int = 5) -> FloatArray:
    """Points (N, 3) after a centred moving average of ``width`` points (edges held)."""
    if len(X) < width:
        return X
    kernel = np.ones(width) / width
    pad = np.pad(X, ((width // 2, width // 2), (0, 0)), mode="edge")
    return np.stack([np.convolve(pad[:, k], kernel, mode="valid") for k in range(3)], axis=1)


def _chord_parameter(X: FloatArray) -> FloatArray:
    """Cumulative chord length (N,) of lightly pre-smoothed points (N, 3)."""
    Xs = _presmoothed(X)
    return arclength(Xs)


def epipolar_weights(
    X_world: ArrayLike, view_a: ViewGeometry, view_b: ViewGeometry, *, min_weight: float = 0.02
) -> FloatArray:
    """Conditioning weights (N,) of triangulated centerline points (N, 3).

    Where the vessel runs inside its epipolar plane (the plane through the
    point and both sources) the epipolar line grazes the trace and the match
    slides along it: a trace error d moves the point by ~ d / sin(phi), phi
    the angle between the vessel tangent and the plane. The weight is
    max(sin^2 phi, min_weight), the inverse of that error variance.
    """
    X = np.asarray(X_world, dtype=float).reshape(-1, 3)
    if len(X) < 3:
        return np.ones(len(X))
    tangent = np.gradient(_presmoothed(X), axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    normal = np.cross(X - view_a.source_world, X - view_b.source_world)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    sin_phi = np.abs(np.einsum("nd,nd->n", tangent, normal))
    return np.maximum(sin_phi**2, min_weight)


SMOOTHING_MM = 1.1


def build_centerline_3d(
    matching: Matching,
    view_a: ViewGeometry,
    view_b: ViewGeometry,
    *,
    spacing_mm: float = 0.25,
    method: str = "paper",
    lam: float | None = None,
    smoothing_mm: float = SMOOTHING_MM,
    weighted: bool = True,
    min_weight: float = 0.02,
    overlap_substitution: bool = True,
) -> Centerline3D:
    """Triangulate a matching into a smooth 3D centerline (world mm).

    Parameters
    ----------
    matching : the point pairs (M >= 4) of one segment.
    view_a, view_b : the views the matching was made with (B calibrated).
    spacing_mm : arc-length spacing of the output points.
    method : triangulation, "paper" (eqs. 2-3) or "dlt".
    lam : smoothing-spline penalty; None derives it from ``smoothing_mm``.
    smoothing_mm : bandwidth of the smoothing spline along the vessel. The
        penalty is lam = (points per mm) * smoothing_mm**4 (a cubic smoothing
        spline's equivalent kernel width scales as (lam / density)^(1/4)).
        A fixed bandwidth replaces generalised cross-validation (GCV), which
        followed the depth noise (docs/benchmarks.md).
    weighted : weight each raw point by its conditioning, sin^2 of the angle
        between the vessel and the epipolar plane (see :func:`epipolar_weights`);
        a trace error of d px moves the point by about d / sin(angle).
    min_weight : floor of those weights.
    overlap_substitution : replace an untrusted view's radius by the other
        view's (step 5 of the module docstring); False keeps both as traced.

    Returns
    -------
    Centerline3D with X_world (K, 3) at uniform arc length, tangents (K, 3),
    radius_a_mm / radius_b_mm (K,) by eq. (11), X_raw_world (M, 3) and the
    matched pixels (M, 2).
    """
    pa = np.asarray(matching.points_a_px, dtype=float)
    pb = np.asarray(matching.points_b_px, dtype=float)
    if len(pa) < 4:
        raise TriangulationError(f"need at least 4 matched pairs, got {len(pa)}")
    if spacing_mm <= 0:
        raise ValueError(f"spacing_mm must be positive, got {spacing_mm}")
    X_raw = triangulate(pa, pb, view_a, view_b, method=method)

    t = _chord_parameter(X_raw)
    keep = np.concatenate([[True], np.diff(t) > 1e-9])
    t_k, X_k = t[keep], X_raw[keep]
    if len(t_k) < 4 or t_k[-1] <= 0:
        raise TriangulationError("the matched pairs collapse to a point in 3D")
    w = epipolar_weights(X_k, view_a, view_b, min_weight=min_weight) if weighted else None
    if lam is None:
        lam = len(t_k) / t_k[-1] * smoothing_mm**4
    spline = make_smoothing_spline(t_k, X_k, w=w, lam=lam)

    # uniform arc length of the smoothed curve, from a dense sampling
    t_dense = np.linspace(t_k[0], t_k[-1], max(20 * len(t_k), 2000))
    X_dense = spline(t_dense)
    s_dense = arclength(X_dense)
    n_out = max(int(np.floor(s_dense[-1] / spacing_mm)) + 1, 2)
    s_out = np.linspace(0.0, s_dense[-1], n_out)
    t_out = np.interp(s_out, s_dense, t_dense)
    X_out = spline(t_out)
    d = spline.derivative()(t_out)
    tangents = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)

    def along(per_point_a: FloatArray, per_point_b: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Per-2D-point values of A (N_a,) and B (N_b,) at the output points (K,) each,
        via the matched indices, as functions of the spline parameter."""
        return (
            np.interp(t_out, t_k, per_point_a[matching.index_a][keep]),
            np.interp(t_out, t_k, per_point_b[matching.index_b][keep]),
        )

    rad_a_px, rad_b_px = along(matching.centerline_a.radius_px, matching.centerline_b.radius_px)
    radius_a_mm = radius_mm_eq11(rad_a_px, X_out, view_a)
    radius_b_mm = radius_mm_eq11(rad_b_px, X_out, view_b)
    overlap_a = np.zeros(len(s_out), dtype=bool)
    overlap_b = np.zeros(len(s_out), dtype=bool)
    fit_a, fit_b = radius_a_mm, radius_b_mm  # each view's own fit, kept for the intervals
    if overlap_substitution:
        rel_a, rel_b = along(matching.centerline_a.reliability, matching.centerline_b.reliability)
        overlap_a, overlap_b = _overlap_stretches(rel_a, rel_b, spacing_mm)
        # An overlap only widens the fitted lumen: replace where the untrusted view is wider.
        # ... or a fit that collapsed beside a touching neighbour (much narrower).
        overlap_a &= (radius_a_mm > radius_b_mm) | (radius_a_mm < _COLLAPSED * radius_b_mm)
        overlap_b &= (radius_b_mm > radius_a_mm) | (radius_b_mm < _COLLAPSED * radius_a_mm)
        radius_a_mm, radius_b_mm = (
            np.where(overlap_a, radius_b_mm, radius_a_mm),
            np.where(overlap_b, radius_a_mm, radius_b_mm),
        )
    substituted = bool(np.any(overlap_a | overlap_b))
    depth_a = depth_b = None
    if matching.centerline_a.depth is not None and matching.centerline_b.depth is not None:
        depth_a, depth_b = along(matching.centerline_a.depth, matching.centerline_b.depth)
    return Centerline3D(
        X_world=X_out,
        s_mm=s_out,
        tangents=tangents,
        radius_a_mm=radius_a_mm,
        radius_b_mm=radius_b_mm,
        X_raw_world=X_raw,
        points_a_px=pa,
        points_b_px=pb,
        overlap_a=overlap_a,
        overlap_b=overlap_b,
        fit_radius_a_mm=fit_a if substituted else None,
        fit_radius_b_mm=fit_b if substituted else None,
        depth_a=depth_a,
        depth_b=depth_b,
    )


#: An untrusted view's radius below this fraction of the other view's is a collapsed fit.
_COLLAPSED = 0.6


def _overlap_stretches(
    reliability_a: FloatArray, reliability_b: FloatArray, spacing_mm: float
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Where each view's radius is replaced by the other's: (M,) bool masks for A and B.

    A view is untrusted where its reliability (M,) is below
    OVERLAP_RELIABILITY, widened by OVERLAP_MARGIN_MM along the uniform
    3D arc (``spacing_mm`` per point); it is replaced only where the other
    view is trusted.
    """
    half = int(np.ceil(OVERLAP_MARGIN_MM / spacing_mm))
    structure = np.ones(2 * half + 1, dtype=bool)
    low_a = binary_dilation(reliability_a < OVERLAP_RELIABILITY, structure)
    low_b = binary_dilation(reliability_b < OVERLAP_RELIABILITY, structure)
    return low_a & ~low_b, low_b & ~low_a


def point_polyline_distance(
    points: ArrayLike, polyline: ArrayLike, *, chunk: int = 256
) -> FloatArray:
    """Distance (N,) from each point (N, D) to a polyline (M, D) (segments, exact).

    Works in any dimension D (pixels or mm); processed in chunks of points.
    """
    P = np.asarray(points, dtype=float)
    L = np.asarray(polyline, dtype=float)
    if P.ndim != 2 or L.ndim != 2 or P.shape[1] != L.shape[1] or len(L) < 1:
        raise ValueError(f"points (N, D) and polyline (M, D) needed, got {P.shape}, {L.shape}")
    if len(L) == 1:
        return np.linalg.norm(P - L[0], axis=1)
    a, seg = L[:-1], np.diff(L, axis=0)  # (M-1, D)
    seg_len2 = np.maximum(np.einsum("md,md->m", seg, seg), 1e-24)
    sq_distance = _sq_distance_2d if P.shape[1] == 2 else _sq_distance_nd
    out = np.empty(len(P))
    for start in range(0, len(P), chunk):
        out[start : start + chunk] = np.sqrt(
            sq_distance(P[start : start + chunk], a, seg, seg_len2).min(axis=1))
    return out


def _sq_distance_nd(p: FloatArray, a: FloatArray, seg: FloatArray,
                    seg_len2: FloatArray) -> FloatArray:
    """Squared distances (n, M-1) of points p (n, D) to the segments a + t seg (M-1, D)."""
    w = p[:, None, :] - a[None, :, :]  # (n, M-1, D)
    u = np.clip(np.einsum("nmd,md->nm", w, seg) / seg_len2, 0.0, 1.0)
    diff = w - u[..., None] * seg[None]
    return np.einsum("nmd,nmd->nm", diff, diff)


def _sq_distance_2d(p: FloatArray, a: FloatArray, seg: FloatArray,
                    seg_len2: FloatArray) -> FloatArray:
    """:func:`_sq_distance_nd` for image points (D = 2), by :func:`segment_feet_2d`."""
    return segment_feet_2d(p, a, seg, seg_len2)[1]


def segment_feet_2d(p: FloatArray, a: FloatArray, seg: FloatArray,
                    seg_len2: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Feet of image points p (n, 2) on the segments a + u seg (S, 2), u in [0, 1]:
    u (n, S) and the squared distances (n, S); ``seg_len2`` (S,) is |seg|^2. The sums
    are per coordinate (einsum's bits for two terms) without (n, S, 2) temporaries."""
    wx, wy = p[:, None, 0] - a[None, :, 0], p[:, None, 1] - a[None, :, 1]
    u = np.clip((wx * seg[:, 0] + wy * seg[:, 1]) / seg_len2, 0.0, 1.0)
    dx, dy = wx - u * seg[:, 0], wy - u * seg[:, 1]
    return u, dx * dx + dy * dy


def _error_stats(dist_px: FloatArray, pixel_mm: float) -> dict:
    stats = {
        "max_px": float(dist_px.max()),
        "min_px": float(dist_px.min()),
        "mean_px": float(dist_px.mean()),
        "rms_px": float(np.sqrt(np.mean(dist_px**2))),
        "median_px": float(np.median(dist_px)),  # not in the paper: robust to a short bad stretch
    }
    stats.update({k.replace("_px", "_mm"): v * pixel_mm for k, v in list(stats.items())})
    stats["n"] = int(len(dist_px))
    return stats


def table3_metrics(
    cl3d: Centerline3D, matching: Matching, view_a: ViewGeometry, view_b: ViewGeometry
) -> dict:
    """The paper's Table 3 for one reconstruction.

    For each view, the distance from every traced 2D centerline point (the
    matching's resampled centerlines) to the back-projection of the 3D
    centerline (the projected polyline of ``cl3d.X_world``): max, min, mean,
    RMS in pixels and in mm at the detector (px * pixel size). "3D": the
    distance between the two rays of each matched pair (mean / max, mm).

    Returns
    -------
    {"a": {max_px, min_px, mean_px, rms_px, max_mm, ..., n}, "b": {...},
     "backprojection_mean_mm", "backprojection_rms_mm" (both views pooled),
     "ray_distance_mean_mm", "ray_distance_max_mm"}
    """
    out: dict = {}
    pooled_mm = []
    for key, view, cl in (
        ("a", view_a, matching.centerline_a),
        ("b", view_b, matching.centerline_b),
    ):
        projected = view.project(cl3d.X_world)
        dist_px = point_polyline_distance(cl.points_px, projected)
        out[key] = _error_stats(dist_px, _pixel_size_mm(view))
        pooled_mm.append(dist_px * _pixel_size_mm(view))
    pooled = np.concatenate(pooled_mm)
    out["backprojection_mean_mm"] = float(pooled.mean())
    out["backprojection_rms_mm"] = float(np.sqrt(np.mean(pooled**2)))
    ray = ray_distance_mm(matching.points_a_px, matching.points_b_px, view_a, view_b)
    out["ray_distance_mean_mm"] = float(ray.mean())
    out["ray_distance_max_mm"] = float(ray.max())
    return out
