"""Vessel centerline, radius and brightness in one view from a few clicks.

Pipeline of :func:`trace_segment` (one segment, one view)::

    vesselness (recon.trace.vesselness: contrast-invariant Hessian ridges, scales in mm)
      ->  snap clicks across the vessel onto its centre (recon.trace.snapping)
      ->  orientation-aware minimal path through the snapped clicks (recon.trace.trace_path)
      ->  intensity mapping of the image (recon.trace.intensity: tag, override or profiles)
      ->  subpixel centre and radius from intensity profiles across the vessel
          (recon.trace.profile_fit: least-squares blurred Beer-Lambert cylinder), iterated
          with normals from the re-centred curve; each fit is weighted by its
          reliability (residual and radius consistency: overlaps are bridged)
      ->  weighted smoothing B-spline at uniform arc length (the paper's NURBS,
          sec. 3.3.1)
      ->  radius (N,) from profiles linearised by the Box-Cox power that fits the
          trace best (so the radius does not depend on the mapping being right),
          brightness (N,) at every point (brightness feeds eq. (7))
      ->  checks: a stretch off the vessel, doubling back or running over itself
          is refused with a one-line message naming the place.

This module is the stage's public face: it re-exports ``TraceError``,
``VesselnessMap``, ``compute_vesselness`` and ``snap_click``.

Pixels are (col, row), 0-based; images are MONOCHROME2 (vessels dark).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage as ndi
from scipy.interpolate import splev, splprep

from recon.trace.guide_catheter import Catheter2D, catheter_runs, find_catheters
from recon.trace.intensity import (
    INTENSITY_CHOICES,
    POWER_OF,
    IntensityMapping,
    ValueScale,
    absorption,
    best_blur,
    best_enhancement,
    best_power,
    geometric_mean,
    is_display_processed,
    normalised_absorption,
    resolve_mapping,
)
from recon.trace.profile_fit import (
    MIN_MAX_SHIFT_PX,
    SampledProfiles,
    fit_along,
    half_width_for,
    sample_along,
    sample_profiles,
    spline_coefficients,
)
from recon.trace.snapping import snap_click
from recon.trace.trace_error import TraceError
from recon.trace.trace_path import find_route_problem, minimal_route
from recon.trace.vesselness import VesselnessMap, compute_vesselness
from recon.types import Centerline2D, arclength

__all__ = [
    "TraceError",
    "VesselnessMap",
    "compute_vesselness",
    "snap_click",
    "trace_segment",
    "BLUR_SIGMA_PX",
]

FloatArray = NDArray[np.float64]

#: Gaussian detector blur (px) assumed by the radius model (phantom renderer's value).
BLUR_SIGMA_PX = 0.7
#: Shift search limit (px) of small vessels (larger vessels search farther).
_MAX_SHIFT_PX = MIN_MAX_SHIFT_PX
_COARSE_SIGMA_PX = 0.4
_FINE_SIGMA_PX = 0.12
#: Passes of (fit across the vessel -> re-centre the curve -> new normals), at most.
_N_REFINE = 4
#: Consecutive fits (1 px apart) at the search limit, one way, that count as a cut corner.
_MIN_LIMIT_RUN = 5
#: Running-median window (points, 1 px apart) of the reference radius; longer than an
#: overlap, so an overlap fitted as one wide tube stands out against it.
_REF_WINDOW_PX = 121
#: A fit wider than the reference radius by more than this fraction loses weight.
_RADIUS_TOL = 0.15
#: A fit whose residual variance exceeds this many times the trace's median loses weight.
_RSS_TOL = 3.0
#: Largest radius (px) the profile tables cover.
_R_CAP_PX = 40.0
#: Tukey's biweight constant (95 % efficiency at the normal) and the least cut-off (px)
#: of the shifts' outlier test.
_TUKEY_C = 4.685
_MIN_CUTOFF_PX = 1.0
#: Lumen radii at each end of a trace over which the radius is held (no end dip).
_END_HOLD = 1.5
#: Box-Cox power of the absorption used for centring before the mapping is known
#: (-log; a symmetric profile stays symmetric under any monotone map).
_PROVISIONAL_POWER = 0.0
#: A point is off the vessel where the response is below this fraction of the
#: trace's median response.
_OFF_VESSEL = 0.3
#: ... or where its fitted radius exceeds this many times the trace's median radius
#: while its attenuation is below _OFF_VESSEL of the median (a shallow wide shadow).
_DIFFUSE_RADIUS = 1.6
#: A route running along a catheter for more than this many of its radii is refused.
_CATHETER_RUN_RADII = 4.0


# -------------------------------------------------------------------- helpers
def _unit_normals(points_px: FloatArray) -> FloatArray:
    """Unit normals (N, 2): central-difference tangents turned by +90 degrees."""
    t = np.gradient(points_px, axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    return np.column_stack([-t[:, 1], t[:, 0]])


def _resample_uniform(points_px: FloatArray, spacing_px: float) -> FloatArray:
    """Polyline (N, 2) resampled at uniform arc length (linear), ends kept."""
    s = arclength(points_px)
    n = max(int(np.ceil(s[-1] / spacing_px)) + 1, 2)
    s_new = np.linspace(0.0, s[-1], n)
    return np.column_stack([np.interp(s_new, s, points_px[:, 0]),
                            np.interp(s_new, s, points_px[:, 1])])


def _smooth_spline(
    points_px: FloatArray, sigma_px: float, spacing_px: float, weights: FloatArray | None = None
) -> FloatArray:
    """Smoothing cubic B-spline through noisy points (N, 2), at uniform arc length.

    The smoothing factor is the expected weighted residual: s = sum(w^2) sigma_px^2
    (splprep); ``weights`` (N,) are relative confidences in (0, 1] (1 = a clean
    profile; a point of weight w may lie sigma_px / w from the curve).
    """
    keep = np.concatenate([[True], np.linalg.norm(np.diff(points_px, axis=0), axis=1) > 1e-6])
    pts = points_px[keep]
    if len(pts) < 4:
        return _resample_uniform(pts, spacing_px)
    weights = np.ones(len(pts)) if weights is None else np.array(weights, float)[keep]
    weights[[0, -1]] = 10.0  # pin the ends at the (refined) end clicks
    s_total = float(np.sum(np.minimum(weights, 1.0) ** 2)) * sigma_px**2
    tck, _ = splprep([pts[:, 0], pts[:, 1]], w=weights, s=s_total, k=3)
    u_dense = np.linspace(0.0, 1.0, max(8 * len(pts), 64))
    dense = np.column_stack(splev(u_dense, tck))
    s = arclength(dense)
    n = max(int(round(s[-1] / spacing_px)) + 1, 2)
    u_new = np.interp(np.linspace(0.0, s[-1], n), s, u_dense)
    return np.column_stack(splev(u_new, tck))


def _reliability(radius_px: FloatArray, rss: FloatArray, fitted: NDArray[np.bool_]) -> FloatArray:
    """Confidence (N,) in (0, 1] of each profile fit along a trace.

    A profile that is not one clean tube (an overlapping, touching or branching
    vessel) fits with a larger residual variance than the trace's typical one, or
    as a tube wider than the vessel's running reference radius. Each cause divides
    the weight; a clean profile has weight 1.
    """
    w = np.full(len(rss), 1e-3)
    if not np.any(fitted):
        return w
    rss_ref = float(np.median(rss[fitted]))
    r_fit = np.interp(np.arange(len(rss)), np.nonzero(fitted)[0], radius_px[fitted])
    n_win = max(int(_REF_WINDOW_PX) | 1, 3)
    r_ref = ndi.median_filter(r_fit, size=n_win, mode="nearest")
    excess = np.clip(r_fit / np.maximum(r_ref, 1e-6) - 1.0 - _RADIUS_TOL, 0.0, None)
    ratio = np.clip(rss / max(_RSS_TOL * rss_ref, 1e-30) - 1.0, 0.0, None)
    w_fit = 1.0 / (1.0 + ratio) / (1.0 + (excess / 0.1) ** 2)
    return np.where(fitted, np.clip(w_fit, 1e-3, 1.0), 1e-3)


def _robust_shift(shift_px: FloatArray, weight: FloatArray,
                  radius_px: FloatArray) -> tuple[FloatArray, FloatArray, float]:
    """Shifts (N,) along the normals of a curve sampled 1 px apart, smoothed along it.

    A weighted Gaussian average (normalised convolution, sigma half a lumen radius,
    at least 1.5 px) with Tukey's biweight reweighting (Beaton & Tukey,
    Technometrics 1974): a fit pulled onto a neighbour at a junction or a crossing
    (a shift far from those around it) gets no weight. Returns the smoothed shifts
    (N,), each fit's inlier weight (N,) in [0, 1] and the fits' scatter (px, a
    robust standard deviation about the smoothed shifts).
    """
    sigma = max(0.5 * float(np.median(radius_px)), 1.5)
    base = np.clip(np.nan_to_num(weight), 0.0, None)
    used = base > 0.5
    x = np.nan_to_num(shift_px)
    inlier = np.ones(len(x))
    smooth, scatter = x, 0.0
    for _ in range(4):
        w = base * inlier
        num = ndi.gaussian_filter1d(w * x, sigma, mode="nearest")
        den = ndi.gaussian_filter1d(w, sigma, mode="nearest")
        smooth = np.where(den > 1e-9, num / np.maximum(den, 1e-12), x)
        resid = np.abs(x - smooth)
        scatter = 1.4826 * float(np.median(resid[used] if np.any(used) else resid))
        u = (x - smooth) / max(_TUKEY_C * scatter, _MIN_CUTOFF_PX)
        inlier = np.where(np.abs(u) < 1.0, (1.0 - u**2) ** 2, 0.0)
    return smooth, inlier, scatter


def _limit_runs(
    shift_px: FloatArray, min_run: int = _MIN_LIMIT_RUN, limit_px: FloatArray | float | None = None
) -> FloatArray:
    """1.0 where the shift (N,) is at the search limit (``limit_px``, per point or one
    value; default :data:`_MAX_SHIFT_PX`) in a run of at least ``min_run``
    consecutive points with the same sign, else 0.0."""
    limit = _MAX_SHIFT_PX if limit_px is None else limit_px
    sign = np.where(np.abs(shift_px) >= np.asarray(limit) - 1e-9, np.sign(shift_px), 0.0)
    out = np.zeros(len(shift_px))
    for value in (-1.0, 1.0):
        labels, n = ndi.label(sign == value)
        if n:
            sizes = np.bincount(labels.ravel())
            long_run = sizes >= min_run
            long_run[0] = False
            out[long_run[labels]] = 1.0
    return out


def _hold_ends(radius_px: FloatArray, spacing_px: float) -> FloatArray:
    """Radius (N,) with the last :data:`_END_HOLD` lumen radii at each end not below
    the values just inside: a profile window that reaches past a vessel's end (or
    into the rounded end of a contrast column) fits a falling radius there, not a
    lesion (a lesion is longer; click beyond it)."""
    r = radius_px.copy()
    near = max(int(round(40.0 / spacing_px)), 1)  # the end's typical radius: first 40 px
    for rv in (r, r[::-1]):  # views: the proximal end, then the distal end
        n_hold = min(int(np.ceil(_END_HOLD * float(np.median(rv[:near])) / spacing_px)),
                     len(rv) // 4)
        if n_hold >= 1:
            rv[:n_hold] = np.maximum(rv[:n_hold], float(np.max(rv[n_hold : 2 * n_hold + 1])))
    return r


def _click_role(i: int, k: int) -> str:
    if i == 0:
        return "proximal end"
    if i == k - 1:
        return "distal end"
    return "waypoint"


def _check_clicks(image_shape: tuple[int, int], clicks: FloatArray, view: str) -> None:
    h, w = image_shape
    if clicks.ndim != 2 or clicks.shape[1] != 2:
        raise TraceError(f"view {view}: clicks must be (K, 2) (col, row), got {clicks.shape}",
                         view=view)
    if len(clicks) < 2:
        raise TraceError(f"view {view}: need at least 2 clicks (proximal, distal), "
                         f"got {len(clicks)}", view=view)
    k = len(clicks)
    for i, (c, r) in enumerate(clicks):
        where = f"view {view}: click {i + 1} ({_click_role(i, k)})"
        if not (np.isfinite(c) and np.isfinite(r)):
            raise TraceError(f"{where} is not a finite (col, row) pair", view=view)
        if not (0.0 <= c <= w - 1 and 0.0 <= r <= h - 1):
            raise TraceError(f"{where} at ({c:.1f}, {r:.1f}) is outside the {w}x{h} image",
                             view=view, near_px=(c, r))
    gaps = np.linalg.norm(clicks[:, None, :] - clicks[None, :, :], axis=2)
    gaps[np.arange(k), np.arange(k)] = np.inf
    i, j = np.unravel_index(np.argmin(gaps), gaps.shape)
    if gaps[i, j] < 2.0:
        i, j = sorted((int(i), int(j)))
        raise TraceError(
            f"view {view}: clicks {i + 1} and {j + 1} are {gaps[i, j]:.1f} px apart "
            "(need at least 2 px)", view=view, near_px=clicks[i],
        )


def _smooth_radius(radius_px: FloatArray, spacing_px: float) -> FloatArray:
    """Light smoothing along the vessel (median 2 px, then Gaussian 1 px).

    A 5 mm stenosis is ~15 px long, well above these widths.
    """
    n_med = max(int(round(2.0 / spacing_px)) | 1, 1)
    r = ndi.median_filter(radius_px, size=n_med, mode="nearest")
    return ndi.gaussian_filter1d(r, 1.0 / spacing_px, mode="nearest")


def _natural_scale(power: float, scale: ValueScale, log_gain: float | None) -> float:
    """Natural absorption units (ln of the intensity ratio) per unit of ``a_power``:
    1 for -log of values linear in intensity; ref / gain for values linear in
    attenuation when the noise told the gain (else 1: unknown)."""
    if abs(power - 1.0) < 1e-9 and log_gain is not None and log_gain > 0:
        return scale.ref / log_gain
    return 1.0


def _power_rss(raw_coef: FloatArray, points_px: FloatArray, normals: FloatArray,
               radius_px: FloatArray, scale: ValueScale, *, search_shift: bool,
               log_gain: float | None = None):
    """Callable giving, for (Box-Cox power, blur px[, enhancement gain, its sigma px]),
    the residual variances (M,) of the profile fits at points (M, 2) of a raw crop
    (``raw_coef``: its cubic spline coefficients; inf where nothing fitted)."""
    reach = np.linspace(-1.0, 1.0, 41) * half_width_for(float(np.median(radius_px)))
    g = geometric_mean(sample_profiles(raw_coef, points_px, normals, reach, 3), scale)
    samples = sample_along(raw_coef, points_px, normals, radius_px, search_shift=search_shift,
                           order=3)  # the same profiles for every key: sampled once
    absorbed: dict[float, SampledProfiles] = {}  # the samples' absorption, per power

    def rss(key: tuple[float, ...]) -> FloatArray:
        power, blur_px, gain, sigma_px = (tuple(key) + (0.0, 0.0))[:4]
        if power not in absorbed:
            absorbed[power] = replace(samples, groups=tuple(
                (*group[:4], normalised_absorption(group[4], power, scale, g))
                for group in samples.groups))
        fit = fit_along(raw_coef, points_px, normals, radius_px, blur_px, 0.25,
                        search_shift=search_shift, order=3,
                        natural_scale=g ** (power - 1.0) * _natural_scale(power, scale, log_gain),
                        enhance=(gain, sigma_px), samples=absorbed[power])
        return np.where(fit.ok, fit.rss, np.inf)

    return rss


def _cached(fn):
    """``fn`` ((power, blur[, gain, sigma]) -> array) remembering its results."""
    memo: dict[tuple[float, ...], FloatArray] = {}

    def wrapped(key: tuple[float, ...]) -> FloatArray:
        k = tuple(round(float(v), 9) for v in (tuple(key) + (0.0, 0.0))[:4])
        if k not in memo:
            memo[k] = fn(k)
        return memo[k]

    return wrapped


# -------------------------------------------------------------------- tracing
def trace_segment(
    image: ArrayLike,
    clicks_px: ArrayLike,
    *,
    vesselness: VesselnessMap | None = None,
    view: str = "A",
    spacing_px: float = 0.5,
    max_snap_px: float = 8.0,
    blur_px: float = BLUR_SIGMA_PX,
    pixel_mm: float | None = None,
    intensity: str | IntensityMapping = "auto",
    relationship: str | None = None,
    estimate_blur: bool = True,
) -> Centerline2D:
    """Trace one vessel segment from its clicks (proximal end, waypoints, distal end).

    Parameters
    ----------
    image : (H, W) float, MONOCHROME2, the stored values.
    clicks_px : (K >= 2, 2) clicks (col, row), proximal first.
    vesselness : the image's :func:`compute_vesselness` (computed if None).
    view : view name used in error messages ("A" or "B").
    spacing_px : arc-length spacing of the output points.
    max_snap_px : farthest a click may be from a vessel's lumen.
    blur_px : Gaussian blur (px) of the radius model (detector blur and pixel
        integration), or the nominal value when ``estimate_blur``.
    pixel_mm : pixel size at the vessel (mm), detector spacing x SOD / SID; sets the
        vesselness scales when ``vesselness`` is None (None: default scales).
    intensity : "auto", "lin" (values linear in X-ray intensity) or "log" (linear in
        attenuation): the mapping of the stored values; "auto" takes the tag when
        it is LIN or LOG, else compares the vessel profiles under both.
        An :class:`~recon.trace.intensity.IntensityMapping` (from
        :func:`~recon.trace.intensity.resolve_mapping`, once per image) is used as given.
    relationship : the file's PixelIntensityRelationship (0028,1040), or None.
    estimate_blur : fit the model's blur along the trace (a grid around
        ``blur_px``); else use ``blur_px``.

    Returns
    -------
    Centerline2D with points_px (N, 2) at uniform arc length from the proximal to
    the distal snapped click, radius_px (N,) corrected for blur and partial volume,
    brightness (N,) = bilinear image value on the centerline (for eq. (7)),
    clicks_px (K, 2) = the snapped clicks moved onto the trace, reliability (N,),
    and the intensity mapping, its reason and the Box-Cox power used.

    Raises
    ------
    TraceError for clicks outside the image, clicks closer than 2 px, fewer than
    2 clicks, a click far from any vessel, no vessel path between clicks, or a
    trace that leaves the vessel, doubles back or runs over itself (the message
    names the place and asks for a waypoint there; ``near_px`` holds it).
    """
    img = np.array(image, dtype=np.float64)  # a copy: the input is never modified
    if img.ndim != 2:
        raise TraceError(f"view {view}: image must be (H, W), got shape {img.shape}", view=view)
    clicks = np.array(clicks_px, dtype=float)
    if clicks.ndim == 1 and clicks.size % 2 == 0:
        clicks = clicks.reshape(-1, 2)
    _check_clicks(img.shape, clicks, view)
    if not spacing_px > 0:
        raise ValueError(f"spacing_px must be positive, got {spacing_px!r}")
    if not isinstance(intensity, IntensityMapping) and intensity not in INTENSITY_CHOICES:
        raise ValueError(f"intensity must be one of {', '.join(INTENSITY_CHOICES)}, "
                         f"got {intensity!r}")
    vmap = vesselness if vesselness is not None else compute_vesselness(img, pixel_mm=pixel_mm)
    if vmap.response.shape != img.shape:
        raise ValueError(
            f"vesselness shape {vmap.response.shape} does not match image {img.shape}"
        )
    k = len(clicks)
    snapped = np.empty_like(clicks)
    for i in range(k):
        try:
            snapped[i], _ = snap_click(vmap, clicks[i], max_distance_px=max_snap_px)
        except TraceError as err:
            raise TraceError(f"view {view}: click {i + 1} ({_click_role(i, k)}): {err}",
                             view=view, near_px=clicks[i]) from None
    catheters = find_catheters(vmap, img, snapped)
    route = minimal_route(vmap, snapped, view=view, catheters=catheters)
    path_px = route.path_px
    _refuse_catheter_runs(path_px, route.click_index, catheters, view)

    # Raw values on a crop around the path (profiles reach ~1.3 r + 3 px + the shift).
    coarse = _smooth_spline(path_px, _COARSE_SIGMA_PX, 1.0)
    r_guess = np.clip(vmap.radius_px_at(coarse), 1.0, _R_CAP_PX)
    pad = int(np.ceil(max(40.0, 1.6 * float(r_guess.max()) + 12.0)))
    c0, r0 = np.maximum(np.floor(path_px.min(axis=0)) - pad, 0).astype(int)
    c1, r1 = np.minimum(np.ceil(path_px.max(axis=0)) + pad + 1, (img.shape[1], img.shape[0]))
    origin = np.array([c0, r0], dtype=float)
    raw = img[r0 : int(r1), c0 : int(c1)]
    raw_coef = spline_coefficients(raw)
    scale = ValueScale.of(raw)

    # The mapping when the user or the tag says it; otherwise a provisional one for
    # centring (centres do not depend on it) and the profiles decide after pass 1.
    if isinstance(intensity, IntensityMapping):
        mapping: IntensityMapping | None = intensity
    elif intensity != "auto" or (relationship or "").strip().upper() in ("LIN", "LOG"):
        mapping = resolve_mapping(img, relationship, intensity)
    else:
        mapping = None
    centring_power = POWER_OF[mapping.mapping] if mapping is not None else _PROVISIONAL_POWER
    absorb = absorption(raw, centring_power, scale)

    # Pass 1: subpixel centres from the profile fit over shifts along the normal,
    # iterated: each pass re-centres the curve on the fitted centres (weighted by
    # their reliability, so an overlap is bridged from the clean profiles on either
    # side) and refits with the new curve's normals, until the trusted shifts are
    # all below 0.3 px.
    for it in range(_N_REFINE):
        normals = _unit_normals(coarse)
        fit = fit_along(absorb, coarse - origin, normals, r_guess, blur_px, 0.25,
                        natural_scale=None)  # centres: the first-order model suffices
        shift, radius1, ok, rss = fit.shift_px, fit.radius_px, fit.ok, fit.rss
        fitted = np.isfinite(rss) & np.isfinite(radius1)
        fitted[[0, -1]] = True
        weight = _reliability(radius1, rss, fitted)
        _, inlier, scatter_px = _robust_shift(shift, weight * fitted, r_guess)
        weight = weight * np.maximum(inlier, 1e-3)
        refined = coarse + shift[:, None] * normals
        trusted = fitted & (weight > 0.5)
        if it == _N_REFINE - 1 or not np.any(np.abs(shift[trusted]) >= 0.3):
            break
        # A run of fits at the search limit, all one way, is a curve off the centre
        # (a cut corner), not a neighbour: follow it so the next pass can resolve it.
        runs = _limit_runs(shift, limit_px=fit.max_shift_px)
        pull = np.where(weight > 0.5, weight, np.maximum(weight, 0.5 * runs))
        coarse = _smooth_spline(refined[fitted], max(_COARSE_SIGMA_PX, scatter_px), 1.0,
                                pull[fitted])
        r_guess = np.interp(np.linspace(0, 1, len(coarse)), np.linspace(0, 1, int(fitted.sum())),
                            np.nan_to_num(radius1[fitted], nan=2.0))
        r_guess = np.clip(r_guess, 1.0, _R_CAP_PX)
    ok[[0, -1]] = True  # keep the ends (refined like the rest)
    refined, weight = refined[ok], weight[ok]

    # Pass 2: the smoothing spline at uniform arc length, then radius at every point
    # from profiles linearised by the Box-Cox power that fits this trace best.
    points = _smooth_spline(refined, max(_FINE_SIGMA_PX, scatter_px), spacing_px, weight)
    normals = _unit_normals(points)
    r_guess = np.interp(
        np.linspace(0, 1, len(points)), np.linspace(0, 1, int(ok.sum())), radius1[ok]
    )
    r_guess = np.clip(np.nan_to_num(r_guess, nan=2.0), 0.5, _R_CAP_PX)
    every = max(int(round(4.0 / spacing_px)), 1)  # profiles 4 px apart for the grids

    def make_rss(log_gain: float | None):
        return _cached(_power_rss(raw_coef, (points - origin)[::every], normals[::every],
                                  r_guess[::every], scale, search_shift=False,
                                  log_gain=log_gain))

    rss_fn = make_rss(None if mapping is None else mapping.log_gain)
    if mapping is None:
        # Each mapping with its own best blur: the shape cannot tell one from the other.
        def profiled(p: float) -> FloatArray:
            b = best_blur(lambda x: rss_fn((p, round(x, 4))), blur_px)[0] if estimate_blur \
                else blur_px
            return rss_fn((p, round(b, 4)))

        mapping = resolve_mapping(img, relationship, "auto", vesselness=vmap, blur_px=blur_px,
                                  rss_of_power=profiled)
        if mapping.log_gain is not None:
            rss_fn = make_rss(mapping.log_gain)
    power = POWER_OF[mapping.mapping]
    notes = []
    # Display-processed: neither mapping is right, so the trace's profiles pick the power
    # when this function resolves the mapping itself ("auto"; a given IntensityMapping,
    # as the pipeline passes, keeps its power), and the display may be edge-enhanced (an
    # unsharp mask, recon.trace.profile_fit). Power, blur and enhancement shape the profile
    # together: two rounds of each in turn.
    fit_power = is_display_processed(relationship) and \
        not isinstance(intensity, IntensityMapping) and intensity == "auto"
    fit_enhance = is_display_processed(relationship)
    prior_power, blur, enhance = power, blur_px, (0.0, 0.0)
    for _ in range(2 if fit_enhance else 1):
        if fit_power:
            power, _ = best_power(lambda p, b=blur, e=enhance: rss_fn((p, b, *e)),
                                  prior_power)
        if estimate_blur:
            blur, _ = best_blur(lambda b, p=power, e=enhance: rss_fn((p, round(b, 4), *e)),
                                blur_px)
            blur = round(blur, 3)
        if fit_enhance:
            enhance = best_enhancement(lambda e, p=power, b=blur: rss_fn((p, b, *e)))
    if fit_power:
        notes.append(f"display-processed: Box-Cox power {power:.2f} fitted")
    if enhance[0] > 0:
        notes.append(f"edge enhancement gain {enhance[0]:.2f}, sigma {enhance[1]:.1f} px "
                     "fitted")
    if estimate_blur:
        notes.append(f"blur {blur:.2f} px fitted")
    fit2 = fit_along(spline_coefficients(absorption(raw, power, scale)), points - origin,
                     normals, r_guess, blur, 0.1, search_shift=False, order=3,
                     natural_scale=_natural_scale(power, scale, mapping.log_gain),
                     enhance=enhance)
    radius, ok2, rss2 = fit2.radius_px, fit2.ok, fit2.rss
    if not np.any(ok2):
        raise TraceError(f"view {view}: no vessel profile could be fitted along the trace",
                         view=view)
    reliability = _reliability(radius, rss2, ok2)
    idx = np.arange(len(points))
    radius = np.interp(idx, idx[ok2], radius[ok2])
    radius = _hold_ends(_smooth_radius(radius, spacing_px), spacing_px)
    # the densitometric signal (recon.lumen.densitometry), smoothed like the radius
    depth = _smooth_radius(np.interp(idx, idx[ok2], fit2.depth[ok2]), spacing_px)
    brightness = ndi.map_coordinates(img, [points[:, 1], points[:, 0]], order=1, mode="nearest")

    # The snapped clicks, moved onto the trace.
    d = np.linalg.norm(points[None, :, :] - snapped[:, None, :], axis=2)
    at = np.argmin(d, axis=1)
    at[0], at[-1] = 0, len(points) - 1
    at = np.maximum.accumulate(at)
    _check_trace(vmap, points, radius, fit2.depth, np.nan_to_num(fit2.radius_px, nan=0.0), at,
                 view)
    reason = "; ".join([mapping.reason, *notes])
    return Centerline2D(
        points_px=points,
        radius_px=radius,
        brightness=brightness,
        clicks_px=points[at],
        reliability=reliability,
        intensity_mapping=mapping.mapping,
        intensity_reason=reason,
        intensity_power=float(power),
        blur_px=float(blur),
        depth=depth,
        catheters_px=tuple(c.points_px for c in catheters),
    )


def _refuse_catheter_runs(path_px: FloatArray, click_index: NDArray[np.int64],
                          catheters: tuple[Catheter2D, ...], view: str) -> None:
    """A TraceError naming the first stretch of the route ``path_px`` (N, 2) that runs
    along a catheter for more than :data:`_CATHETER_RUN_RADII` of its radii."""
    if not catheters:
        return
    min_run = _CATHETER_RUN_RADII * min(float(np.median(c.radius_px)) for c in catheters)
    runs = catheter_runs(path_px, catheters, min_run)
    if not runs:
        return
    i, j = runs[0]
    near = path_px[(i + j) // 2]
    leg = int(np.searchsorted(click_index, (i + j) // 2, side="right"))
    leg = int(np.clip(leg, 1, len(click_index) - 1))
    raise TraceError(
        f"view {view}: the trace between click {leg} and click {leg + 1} runs along the "
        f"guiding catheter near ({near[0]:.0f}, {near[1]:.0f}); add a waypoint on the "
        "vessel there, or, if the vessel runs under the catheter there in this view, "
        "choose another view", view=view, near_px=near)


def _check_trace(vmap: VesselnessMap, points: FloatArray, radius: FloatArray,
                 depth: FloatArray, fit_radius: FloatArray, click_at: NDArray[np.int64],
                 view: str) -> None:
    """Refuse a trace that leaves the vessel, doubles back or runs over itself.

    ``depth`` (N,) and ``fit_radius`` (N,) are each point's fitted attenuation and
    radius. A point is off the vessel where both the ridge measure and the fitted
    profile's mass (attenuation x radius^2, ~ the integrated absorption across)
    are below :data:`_OFF_VESSEL` of their medians along the trace (a crossing's
    centre has a weak ridge but a heavy profile; a gap has neither), or where the
    profile is a shallow wide shadow: attenuation below :data:`_OFF_VESSEL` and
    radius above :data:`_DIFFUSE_RADIUS` times their medians (the contrast-invariant
    ridge also answers on a faint background structure; a vessel whose contrast
    fades keeps its calibre).
    """
    ridge = vmap.response if vmap.ridge is None else vmap.ridge
    resp = ndi.map_coordinates(ridge, [points[:, 1], points[:, 0]], order=1,
                               mode="nearest")
    mass = depth * fit_radius**2
    deep = mass >= _OFF_VESSEL * float(np.median(mass))
    diffuse = (depth < _OFF_VESSEL * float(np.median(depth))) & \
        (fit_radius > _DIFFUSE_RADIUS * float(np.median(fit_radius)))
    on_vessel = ((resp >= _OFF_VESSEL * float(np.median(resp))) | deep) & ~diffuse
    problem = find_route_problem(points, radius, on_vessel)
    if problem is None:
        return
    seg = int(np.clip(np.searchsorted(click_at, problem.index, side="right") - 1, 0,
                      len(click_at) - 2))
    near = points[problem.index]
    # A hairpin is also what a vessel that folds back in projection shows (a bend seen
    # along the ray); there a waypoint does not help, another view does.
    fold = (", or, if the vessel folds back on itself there in this view, choose another "
            "view") if problem.kind == "doubles back" else ""
    raise TraceError(
        f"view {view}: the trace between click {seg + 1} and click {seg + 2} "
        f"{problem.kind} near ({near[0]:.0f}, {near[1]:.0f}); add a waypoint on the "
        f"vessel there{fold}",
        view=view, near_px=near,
    )
