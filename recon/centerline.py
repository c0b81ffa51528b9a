"""Vessel centerline, radius and brightness in one view from a few clicks.

Pipeline of :func:`trace_segment` (one segment, one view)::

    vesselness (Hessian, Frangi)  ->  snap clicks to the ridge
      ->  minimal-cost path through the snapped clicks
      ->  subpixel centre and radius from intensity profiles across the vessel
          (least-squares fit of a blurred Beer-Lambert cylinder), iterated with
          normals from the re-centred curve; each fit is weighted by its
          reliability (residual and radius consistency: overlaps are bridged)
      ->  weighted smoothing B-spline at uniform arc length (the paper's NURBS,
          sec. 3.3.1)
      ->  radius (N,) and brightness (N,) at every point (brightness feeds eq. (7)).

Pixels are (col, row), 0-based; images are MONOCHROME2 (vessels dark).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage as ndi
from scipy.interpolate import splev, splprep
from skimage.graph import route_through_array

from recon.errors import CoronaryError
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
#: Response (after normalisation to [0, 1]) above which a pixel counts as vessel.
_RIDGE_THRESHOLD = 0.15
#: Around a click a vessel only half as strong as the strongest ridge within reach
#: still counts (vesselness is normalised per image, so a faint distal vessel can
#: stay below _RIDGE_THRESHOLD); never below this floor (image noise is < 0.02).
_RIDGE_FLOOR = 0.05
_FRANGI_BETA = 0.5
_PROFILE_STEP_PX = 0.5
_COARSE_SIGMA_PX = 0.4
_FINE_SIGMA_PX = 0.12
_MAX_SHIFT_PX = 2.0
_SHIFT_STEP_PX = 0.5
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


class TraceError(CoronaryError):
    """A click or segment that cannot be traced; the one-line message names the view and click."""


@dataclass(frozen=True, eq=False)
class VesselnessMap:
    """Multiscale dark-ridge response of one image, computed once and reused.

    Attributes
    ----------
    response : (H, W) float32 in [0, 1], zero outside ``valid``.
    scale_px : (H, W) float32, the Gaussian sigma (px) of the strongest response.
    valid : (H, W) bool, inside the collimated field and away from the image edge.
    """

    response: NDArray[np.float32]
    scale_px: NDArray[np.float32]
    valid: NDArray[np.bool_]

    @property
    def shape(self) -> tuple[int, int]:
        return self.response.shape  # type: ignore[return-value]


# ----------------------------------------------------------------- vesselness
def _field_mask(image: NDArray[np.float32], margin_px: float) -> NDArray[np.bool_]:
    """Collimated field (H, W) bool, eroded by ``margin_px`` and away from the image edge.

    The black collimator border is the near-constant dark band touching the image
    edge. When the outer frame is much darker than the image median, the field is
    the convex hull of the largest bright region (vessels touching the border are
    filled back in); otherwise the whole image is the field.
    """
    h, w = image.shape
    frame = np.concatenate([image[:2].ravel(), image[-2:].ravel(),
                            image[:, :2].ravel(), image[:, -2:].ravel()])
    lo = float(np.median(frame))
    mid = float(np.median(image))
    p1, p99 = np.percentile(image, [1.0, 99.0])
    field = np.ones((h, w), dtype=bool)
    if mid - lo > 0.3 * max(float(p99 - p1), 1e-12):
        bright = image > lo + 0.5 * (mid - lo)
        labels, n = ndi.label(bright)
        if n > 0:
            sizes = np.bincount(labels.ravel())
            sizes[0] = 0
            largest = labels == int(np.argmax(sizes))
            field = _convex_fill(largest)
    field[0, :] = field[-1, :] = field[:, 0] = field[:, -1] = False
    dist = ndi.distance_transform_edt(field)
    return dist > margin_px


def _convex_fill(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Convex hull (H, W) bool of a mask (cv2 on the boundary points)."""
    import cv2

    rows, cols = np.nonzero(mask)
    pts = np.column_stack([cols, rows]).astype(np.int32)
    hull = cv2.convexHull(pts)
    out = np.zeros(mask.shape, dtype=np.uint8)
    cv2.fillConvexPoly(out, hull, 1)
    return out.astype(bool)


def _parabola_vertex_offset(f0: NDArray, f1: NDArray, f2: NDArray) -> NDArray:
    """Offset in [-0.5, 0.5] samples of the vertex of the parabola through three
    equally spaced values around a discrete minimum (0 where it is not convex)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        denom = f0 - 2.0 * f1 + f2
        delta = np.where(np.isfinite(denom) & (denom > 0), 0.5 * (f0 - f2) / denom, 0.0)
    return np.clip(np.nan_to_num(delta), -0.5, 0.5)


def compute_vesselness(
    image: ArrayLike, *, sigmas_px: tuple[float, ...] = (1.0, 1.5, 2.0, 3.0, 4.0)
) -> VesselnessMap:
    """Frangi vesselness for dark tubes, max over scales, normalised to [0, 1].

    Parameters
    ----------
    image : (H, W) float, MONOCHROME2 (vessels darker than the background).
    sigmas_px : Gaussian scales (px) of the Hessian.

    Returns
    -------
    VesselnessMap with response (H, W) in [0, 1] (zero outside the collimated
    field), the best scale (H, W) and the field mask (H, W).
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 2 or min(img.shape) < 8:
        raise ValueError(f"image must be (H, W) with H, W >= 8, got shape {img.shape}")
    if not np.all(np.isfinite(img)):
        raise ValueError("image contains NaN or infinite values")
    sigmas = np.asarray(sigmas_px, dtype=float)
    if sigmas.ndim != 1 or len(sigmas) == 0 or np.any(sigmas <= 0):
        raise ValueError(f"sigmas_px must be positive, got {sigmas_px!r}")
    valid = _field_mask(img, margin_px=2.0 * float(sigmas.max()) + 1.0)

    # Frangi et al. (1998) 2D: eigenvalues |l1| <= |l2| of the sigma^2-normalised
    # Hessian; dark ridge <=> l2 > 0 across the vessel.
    blob_terms, struct_terms = [], []
    for s in sigmas:
        hrr = ndi.gaussian_filter(img, s, order=(2, 0)) * s * s
        hcc = ndi.gaussian_filter(img, s, order=(0, 2)) * s * s
        hrc = ndi.gaussian_filter(img, s, order=(1, 1)) * s * s
        half_tr = 0.5 * (hrr + hcc)
        disc = np.sqrt(0.25 * (hrr - hcc) ** 2 + hrc * hrc)
        e1, e2 = half_tr + disc, half_tr - disc
        swap = np.abs(e1) > np.abs(e2)
        l1 = np.where(swap, e2, e1)
        l2 = np.where(swap, e1, e2)
        rb2 = (l1 / np.where(np.abs(l2) > 1e-12, l2, 1e-12)) ** 2
        s2 = l1 * l1 + l2 * l2
        blob = np.exp(-rb2 / (2.0 * _FRANGI_BETA**2)) * (l2 > 0)
        blob_terms.append(blob.astype(np.float32))
        struct_terms.append(s2.astype(np.float32))
    s2_all = np.stack(struct_terms)
    s2_valid = s2_all[:, valid] if np.any(valid) else s2_all.reshape(len(sigmas), -1)
    c2 = max(float(np.max(s2_valid)) * 0.25, 1e-20)  # c = half the max Hessian norm
    v_all = np.stack(blob_terms) * (1.0 - np.exp(-s2_all / (2.0 * c2)))
    best = np.argmax(v_all, axis=0)
    response = np.take_along_axis(v_all, best[None], axis=0)[0]
    response[~valid] = 0.0
    inside = response[valid]
    norm = float(np.percentile(inside, 99.9)) if inside.size else 0.0
    if norm > 0:
        response = np.clip(response / norm, 0.0, 1.0)
    return VesselnessMap(
        response=response.astype(np.float32),
        scale_px=sigmas.astype(np.float32)[best],
        valid=valid,
    )


# ------------------------------------------------------------------- snapping
def snap_click(
    vmap: VesselnessMap, point_px: ArrayLike, *, max_distance_px: float = 8.0
) -> tuple[FloatArray, float]:
    """Move a click onto the centre of the nearest strong ridge.

    Parameters
    ----------
    vmap : the image's vesselness.
    point_px : (2,) click (col, row).
    max_distance_px : farthest a vessel pixel may be from the click.

    Returns
    -------
    snapped_px : (2,) (col, row) of the ridge pixel.
    distance_px : distance from the click to the snapped pixel.

    Raises
    ------
    TraceError if no vessel pixel lies within ``max_distance_px``.
    """
    p = np.asarray(point_px, dtype=float).reshape(-1)
    if p.shape != (2,) or not np.all(np.isfinite(p)):
        raise TraceError(f"click must be a finite (col, row) pair, got {point_px!r}")
    h, w = vmap.response.shape
    col, row = float(p[0]), float(p[1])
    search = max(float(max_distance_px), 0.0) + 8.0
    r0, r1 = max(int(np.floor(row - search)), 0), min(int(np.ceil(row + search)) + 1, h)
    c0, c1 = max(int(np.floor(col - search)), 0), min(int(np.ceil(col + search)) + 1, w)
    where = f"click at ({col:.1f}, {row:.1f})"
    if r0 >= r1 or c0 >= c1:
        raise TraceError(f"{where} is outside the {w}x{h} image")
    resp = vmap.response[r0:r1, c0:c1]
    rr, cc = np.mgrid[r0:r1, c0:c1]
    dist = np.hypot(cc - col, rr - row)
    reach_peak = float(resp[dist <= max_distance_px].max(initial=0.0))
    strong = resp >= float(np.clip(0.5 * reach_peak, _RIDGE_FLOOR, _RIDGE_THRESHOLD))
    if not np.any(strong):
        raise TraceError(f"{where} is more than {search:.0f} px from any vessel")
    d_near = float(dist[strong].min())
    if d_near > max_distance_px:
        raise TraceError(
            f"{where} is {d_near:.1f} px from any vessel (max {max_distance_px:g} px)"
        )
    # The nearest strong pixel lies on the vessel's near edge: climb to the ridge
    # centre within about one vessel radius of it, staying on strong pixels.
    i_near = np.argmin(np.where(strong, dist, np.inf))
    cn, rn = cc.ravel()[i_near], rr.ravel()[i_near]
    reach = max(2.0, 2.0 * float(vmap.scale_px[rn, cn]))
    near = strong & (np.hypot(cc - cn, rr - rn) <= reach)
    labels, _ = ndi.label(strong)
    near &= labels == labels.ravel()[i_near]
    # Stay level with the click along the vessel: the vessel axis is the principal
    # direction of the strong pixels around (response-weighted), and the snapped
    # pixel is the strongest one within 1 px of the line across the vessel.
    around = strong & (labels == labels.ravel()[i_near]) & (np.hypot(cc - cn, rr - rn) <= 3 * reach)
    wts = resp[around]
    xy = np.column_stack([cc[around], rr[around]]).astype(float)
    centred = xy - np.average(xy, axis=0, weights=wts)
    cov = (centred * wts[:, None]).T @ centred
    axis = np.linalg.eigh(cov)[1][:, -1]  # (2,) unit vessel direction (col, row)
    along = np.abs((cc - col) * axis[0] + (rr - row) * axis[1])
    level = near & (along <= 1.0)
    score = np.where(level if np.any(level) else near, resp, -1.0)
    i_best = np.argmax(score)
    snapped = np.array([cc.ravel()[i_best], rr.ravel()[i_best]], dtype=float)
    return snapped, float(np.hypot(*(snapped - p)))


# -------------------------------------------------------------- profile model
@lru_cache(maxsize=32)
def _profile_lut(
    half_width_px: float, blur_px: float, r_min: float, r_max: float, r_step: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Least-squares tables for the blurred-cylinder profile model.

    Model of the absorption profile across a vessel, offset x (px) from its centre::

        a(x) = c0 + c1 x + b * (G_blur * 2 sqrt(r^2 - x^2))(x)

    (Beer-Lambert: log-intensity is the chord length through the lumen times the
    attenuation, convolved with the detector blur.)

    Returns
    -------
    offsets : (L,) sample offsets (px) across the vessel.
    radii : (R,) radii (px) of the table.
    design_flat : (L, 3R) the design matrices D_r side by side.
    pinv_flat : (L, 3R) the pseudo-inverses (D_r^T D_r)^-1 D_r^T, transposed, side by side.
    """
    n_half = int(round(half_width_px / _PROFILE_STEP_PX))
    offsets = np.arange(-n_half, n_half + 1) * _PROFILE_STEP_PX
    radii = np.arange(r_min, r_max + 0.5 * r_step, r_step)
    # Template (R, L): the chord 2 sqrt(r^2 - x^2) convolved with the Gaussian blur,
    # by quadrature on a fine grid (one matrix product).
    fine_step = 0.02
    fine = np.arange(-r_max - 0.5, r_max + 0.5 + fine_step, fine_step)
    chord = 2.0 * np.sqrt(np.clip(radii[:, None] ** 2 - fine[None, :] ** 2, 0.0, None))
    sigma = max(blur_px, 0.5 * fine_step)
    kernel = np.exp(-0.5 * ((offsets[None, :] - fine[:, None]) / sigma) ** 2)  # (F, L)
    template = chord @ (kernel * (fine_step / (np.sqrt(2.0 * np.pi) * sigma)))
    design = np.stack(
        [np.ones_like(template), np.broadcast_to(offsets, template.shape), template], axis=1
    )  # (R, 3, L)
    gram = design @ design.transpose(0, 2, 1)
    pinv = np.linalg.inv(gram) @ design  # (R, 3, L)
    n_r, n_l = len(radii), len(offsets)
    design_flat = design.reshape(3 * n_r, n_l).T.copy()
    return offsets, radii, design_flat, pinv.reshape(3 * n_r, n_l).T.copy()


def _fit_profiles(
    profiles: FloatArray, half_width_px: float, blur_px: float, r_max: float, r_step: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Best radius for each absorption profile by a table search over r.

    Parameters
    ----------
    profiles : (M, L) absorption samples at the table's offsets.

    Returns
    -------
    rss : (M,) residual sum of squares of the best fit (inf if no dark vessel fits).
    radius_px : (M,) radius, refined by a parabola through the RSS minimum.
    depth : (M,) fitted attenuation b (per px of chord).
    """
    _, radii, design_flat, pinv_flat = _profile_lut(half_width_px, blur_px, 0.3, r_max, r_step)
    m_prof = len(profiles)
    u = (profiles @ design_flat).reshape(m_prof, -1, 3)  # (M, R, 3)  D_r^T p
    coef = (profiles @ pinv_flat).reshape(m_prof, -1, 3)  # (M, R, 3)  least-squares c0, c1, b
    # RSS = |p|^2 - p^T D_r (D_r^T D_r)^-1 D_r^T p
    rss = np.einsum("ml,ml->m", profiles, profiles)[:, None] - np.einsum("mrk,mrk->mr", u, coef)
    rss = np.where(coef[:, :, 2] > 0, rss, np.inf)
    best = np.argmin(rss, axis=1)
    m = np.arange(len(profiles))
    i = np.clip(best, 1, len(radii) - 2)
    delta = _parabola_vertex_offset(rss[m, i - 1], rss[m, i], rss[m, i + 1])
    radius = radii[i] + delta * (radii[1] - radii[0])
    radius = np.where(best == i, radius, radii[best])
    return rss[m, best], radius, coef[m, best, 2]


def _absorption(image: FloatArray) -> FloatArray:
    """Absorption image (H, W) = -log(I) (Beer-Lambert), I floored at 1e-3 of its median.

    An image with a non-positive median (not an intensity image) is used as -I.
    """
    med = float(np.median(image))
    if med <= 0:
        return -image
    return -np.log(np.maximum(image, 1e-3 * med))


def _sample_profiles(
    absorb: FloatArray, points_px: FloatArray, normals: FloatArray, offsets: FloatArray
) -> FloatArray:
    """Bilinear samples (N, L) at points_px + offsets * normals."""
    pos = points_px[:, None, :] + offsets[None, :, None] * normals[:, None, :]  # (N, L, 2)
    coords = np.stack([pos[..., 1].ravel(), pos[..., 0].ravel()])
    return ndi.map_coordinates(absorb, coords, order=1, mode="nearest").reshape(pos.shape[:2])


def _half_width_for(radius_px: float) -> float:
    """Profile half-width (px) used for a vessel of about ``radius_px``."""
    classes = (5.0, 6.0, 7.0, 8.0, 9.5, 11.0, 13.0, 15.0, 17.5, 20.0, 23.0, 26.0)
    need = 1.3 * radius_px + 3.0  # the edges plus ~3 blur widths, but no farther:
    # a wider window lets a neighbouring vessel pull the fit
    for c in classes:
        if c >= need:
            return c
    return classes[-1]


def _fit_along(
    absorb: FloatArray,
    points_px: FloatArray,
    normals: FloatArray,
    radius_guess_px: FloatArray,
    shifts_px: FloatArray,
    blur_px: float,
    r_step: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Fit the cylinder model at every point, over shifts along the normal.

    Returns shift_px (N,), radius_px (N,), ok (N,) bool and the residual variance
    (N,) of the best fit (large where the profile is not a single clean tube: an
    overlapping or touching vessel).
    """
    n = len(points_px)
    shift_out = np.zeros(n)
    radius_out = np.full(n, np.nan)
    rss_out = np.full(n, np.inf)
    half = np.array([_half_width_for(r) for r in radius_guess_px])
    for hw in np.unique(half):
        sel = np.nonzero(half == hw)[0]
        offsets = _profile_lut(hw, blur_px, 0.3, hw - 1.0, r_step)[0]
        # Sample once on the union grid of all shifted offsets.
        all_offsets = (shifts_px[:, None] + offsets[None, :]).ravel()
        prof = _sample_profiles(absorb, points_px[sel], normals[sel], all_offsets)
        prof = prof.reshape(len(sel) * len(shifts_px), len(offsets))
        rss, rad, _ = _fit_profiles(prof, hw, blur_px, hw - 1.0, r_step)
        rss = rss.reshape(len(sel), len(shifts_px))
        rad = rad.reshape(len(sel), len(shifts_px))
        k = np.argmin(rss, axis=1)
        j = np.arange(len(sel))
        shift_out[sel] = shifts_px[k]
        radius_out[sel] = rad[j, k]
        rss_out[sel] = rss[j, k] / (len(offsets) - 4)
        if len(shifts_px) >= 3:  # parabolic refinement of the shift
            kk = np.clip(k, 1, len(shifts_px) - 2)
            d = _parabola_vertex_offset(rss[j, kk - 1], rss[j, kk], rss[j, kk + 1])
            step = shifts_px[1] - shifts_px[0]
            shift_out[sel] = np.where(kk == k, shifts_px[kk] + d * step, shifts_px[k])
    ok = np.isfinite(rss_out) & np.isfinite(radius_out)
    if len(shifts_px) >= 3:
        ok &= np.abs(shift_out) < shifts_px.max() - 1e-9
    return shift_out, radius_out, ok, rss_out


# -------------------------------------------------------------------- tracing
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


def _limit_runs(shift_px: FloatArray, min_run: int = _MIN_LIMIT_RUN) -> FloatArray:
    """1.0 where the shift (N,) is at the search limit in a run of at least
    ``min_run`` consecutive points with the same sign, else 0.0."""
    sign = np.where(np.abs(shift_px) >= _MAX_SHIFT_PX - 1e-9, np.sign(shift_px), 0.0)
    out = np.zeros(len(shift_px))
    for value in (-1.0, 1.0):
        labels, n = ndi.label(sign == value)
        if n:
            sizes = np.bincount(labels.ravel())
            long_run = sizes >= min_run
            long_run[0] = False
            out[long_run[labels]] = 1.0
    return out


def _click_role(i: int, k: int) -> str:
    if i == 0:
        return "proximal end"
    if i == k - 1:
        return "distal end"
    return "waypoint"


def _check_clicks(image_shape: tuple[int, int], clicks: FloatArray, view: str) -> None:
    h, w = image_shape
    if clicks.ndim != 2 or clicks.shape[1] != 2:
        raise TraceError(f"view {view}: clicks must be (K, 2) (col, row), got {clicks.shape}")
    if len(clicks) < 2:
        raise TraceError(f"view {view}: need at least 2 clicks (proximal, distal), "
                         f"got {len(clicks)}")
    k = len(clicks)
    for i, (c, r) in enumerate(clicks):
        where = f"view {view}: click {i + 1} ({_click_role(i, k)})"
        if not (np.isfinite(c) and np.isfinite(r)):
            raise TraceError(f"{where} is not a finite (col, row) pair")
        if not (0.0 <= c <= w - 1 and 0.0 <= r <= h - 1):
            raise TraceError(f"{where} at ({c:.1f}, {r:.1f}) is outside the {w}x{h} image")
    gaps = np.linalg.norm(clicks[:, None, :] - clicks[None, :, :], axis=2)
    gaps[np.arange(k), np.arange(k)] = np.inf
    i, j = np.unravel_index(np.argmin(gaps), gaps.shape)
    if gaps[i, j] < 2.0:
        i, j = sorted((int(i), int(j)))
        raise TraceError(
            f"view {view}: clicks {i + 1} and {j + 1} are {gaps[i, j]:.1f} px apart "
            "(need at least 2 px)"
        )


def _minimal_path(
    vmap: VesselnessMap, clicks_px: FloatArray, view: str
) -> FloatArray:
    """Minimal-cost pixel path (M, 2) (col, row) through the snapped clicks in order."""
    h, w = vmap.response.shape
    lo = clicks_px.min(axis=0)
    hi = clicks_px.max(axis=0)
    margin = 20.0 + 0.15 * float(np.max(hi - lo))
    c0, r0 = (np.maximum(np.floor(lo - margin), 0)).astype(int)
    c1 = int(min(np.ceil(hi[0] + margin) + 1, w))
    r1 = int(min(np.ceil(hi[1] + margin) + 1, h))
    resp = vmap.response[r0:r1, c0:c1].astype(np.float64)
    cost = 1.0 / (1e-3 + resp**2)
    pieces = []
    k = len(clicks_px)
    for i in range(k - 1):
        start = (int(round(clicks_px[i, 1])) - r0, int(round(clicks_px[i, 0])) - c0)
        end = (int(round(clicks_px[i + 1, 1])) - r0, int(round(clicks_px[i + 1, 0])) - c0)
        idx, _ = route_through_array(cost, start, end, fully_connected=True, geometric=True)
        idx = np.asarray(idx, dtype=float)
        on_vessel = resp[idx[:, 0].astype(int), idx[:, 1].astype(int)] >= 0.5 * _RIDGE_THRESHOLD
        off = 1.0 - float(np.mean(on_vessel))
        if off > 0.3:
            raise TraceError(
                f"view {view}: no vessel path between click {i + 1} and click {i + 2} "
                f"({100 * off:.0f}% of the best route is off any vessel)"
            )
        pieces.append(idx if i == 0 else idx[1:])
    path_rc = np.concatenate(pieces)
    return np.column_stack([path_rc[:, 1] + c0, path_rc[:, 0] + r0])


def _smooth_radius(radius_px: FloatArray, spacing_px: float) -> FloatArray:
    """Light smoothing along the vessel (median 2 px, then Gaussian 1 px).

    A 5 mm stenosis is ~15 px long, well above these widths.
    """
    n_med = max(int(round(2.0 / spacing_px)) | 1, 1)
    r = ndi.median_filter(radius_px, size=n_med, mode="nearest")
    return ndi.gaussian_filter1d(r, 1.0 / spacing_px, mode="nearest")


def trace_segment(
    image: ArrayLike,
    clicks_px: ArrayLike,
    *,
    vesselness: VesselnessMap | None = None,
    view: str = "A",
    spacing_px: float = 0.5,
    max_snap_px: float = 8.0,
    blur_px: float = BLUR_SIGMA_PX,
) -> Centerline2D:
    """Trace one vessel segment from its clicks (proximal end, waypoints, distal end).

    Parameters
    ----------
    image : (H, W) float, MONOCHROME2.
    clicks_px : (K >= 2, 2) clicks (col, row), proximal first.
    vesselness : the image's :func:`compute_vesselness` (computed if None).
    view : view name used in error messages ("A" or "B").
    spacing_px : arc-length spacing of the output points.
    max_snap_px : farthest a click may be from a vessel.
    blur_px : Gaussian detector blur (px) of the radius model.

    Returns
    -------
    Centerline2D with points_px (N, 2) at uniform arc length from the proximal to
    the distal snapped click, radius_px (N,) corrected for blur and partial volume,
    brightness (N,) = bilinear image value on the centerline (for eq. (7)), and
    clicks_px (K, 2) = the snapped clicks moved onto the trace.

    Raises
    ------
    TraceError for clicks outside the image, clicks closer than 2 px, fewer than
    2 clicks, a click far from any vessel, or no vessel path between clicks.
    """
    img = np.array(image, dtype=np.float64)  # a copy: the input is never modified
    if img.ndim != 2:
        raise TraceError(f"view {view}: image must be (H, W), got shape {img.shape}")
    clicks = np.array(clicks_px, dtype=float)
    if clicks.ndim == 1 and clicks.size % 2 == 0:
        clicks = clicks.reshape(-1, 2)
    _check_clicks(img.shape, clicks, view)
    if not spacing_px > 0:
        raise ValueError(f"spacing_px must be positive, got {spacing_px!r}")
    vmap = vesselness if vesselness is not None else compute_vesselness(img)
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
            raise TraceError(f"view {view}: click {i + 1} ({_click_role(i, k)}): {err}") from None
    path_px = _minimal_path(vmap, snapped, view)

    # Absorption on a crop around the path (profiles reach at most ~30 px out).
    pad = 40
    c0, r0 = np.maximum(np.floor(path_px.min(axis=0)) - pad, 0).astype(int)
    c1, r1 = np.minimum(np.ceil(path_px.max(axis=0)) + pad + 1, (img.shape[1], img.shape[0]))
    origin = np.array([c0, r0], dtype=float)
    absorb = _absorption(img[r0 : int(r1), c0 : int(c1)])
    # Pass 1: a coarse smooth curve through the pixel path, then subpixel centres
    # from the profile fit over shifts along the normal, iterated: each pass
    # re-centres the curve on the fitted centres (weighted by their reliability, so
    # an overlap is bridged from the clean profiles on either side) and refits with
    # the new curve's normals, until the trusted shifts are all below 0.3 px.
    coarse = _smooth_spline(path_px, _COARSE_SIGMA_PX, 1.0)
    scale = ndi.map_coordinates(vmap.scale_px, [coarse[:, 1], coarse[:, 0]], order=0,
                                mode="nearest")
    r_guess = np.clip(1.6 * scale + 0.5, 1.0, 14.0)
    shifts = np.arange(-_MAX_SHIFT_PX, _MAX_SHIFT_PX + 1e-4, _SHIFT_STEP_PX)
    for it in range(_N_REFINE):
        normals = _unit_normals(coarse)
        shift, radius1, ok, rss = _fit_along(
            absorb, coarse - origin, normals, r_guess, shifts, blur_px, 0.25
        )
        fitted = np.isfinite(rss) & np.isfinite(radius1)
        fitted[[0, -1]] = True
        weight = _reliability(radius1, rss, fitted)
        refined = coarse + shift[:, None] * normals
        trusted = fitted & (weight > 0.5)
        if it == _N_REFINE - 1 or not np.any(np.abs(shift[trusted]) >= 0.3):
            break
        # A run of fits at the search limit, all one way, is a curve off the centre
        # (a cut corner), not a neighbour: follow it so the next pass can resolve it.
        pull = np.where(weight > 0.5, weight, np.maximum(weight, 0.5 * _limit_runs(shift)))
        coarse = _smooth_spline(refined[fitted], _COARSE_SIGMA_PX, 1.0, pull[fitted])
        r_guess = np.interp(np.linspace(0, 1, len(coarse)), np.linspace(0, 1, int(fitted.sum())),
                            np.nan_to_num(radius1[fitted], nan=2.0))
        r_guess = np.clip(r_guess, 1.0, 14.0)
    ok[[0, -1]] = True  # keep the ends (refined like the rest)
    refined, weight = refined[ok], weight[ok]

    # Pass 2: the smoothing spline at uniform arc length, then radius at every point.
    points = _smooth_spline(refined, _FINE_SIGMA_PX, spacing_px, weight)
    normals = _unit_normals(points)
    r_guess = np.interp(
        np.linspace(0, 1, len(points)), np.linspace(0, 1, int(ok.sum())), radius1[ok]
    )
    r_guess = np.nan_to_num(r_guess, nan=2.0)
    _, radius, ok2, rss2 = _fit_along(
        absorb, points - origin, normals, r_guess, np.array([0.0]), blur_px, 0.1
    )
    if not np.any(ok2):
        raise TraceError(f"view {view}: no vessel profile could be fitted along the trace")
    reliability = _reliability(radius, rss2, ok2)
    idx = np.arange(len(points))
    radius = np.interp(idx, idx[ok2], radius[ok2])
    radius = _smooth_radius(radius, spacing_px)
    brightness = ndi.map_coordinates(img, [points[:, 1], points[:, 0]], order=1, mode="nearest")

    # The snapped clicks, moved onto the trace.
    d = np.linalg.norm(points[None, :, :] - snapped[:, None, :], axis=2)
    on_trace = points[np.argmin(d, axis=1)]
    on_trace[0], on_trace[-1] = points[0], points[-1]
    return Centerline2D(
        points_px=points,
        radius_px=radius,
        brightness=brightness,
        clicks_px=on_trace,
        reliability=reliability,
    )
