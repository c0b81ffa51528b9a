"""Centre and radius of a vessel from intensity profiles across it.

Model of the absorption profile across a vessel, offset x (px) from its centre::

    a(x) = c0 + c1 x + b * T_r(x),   T_r = G_blur * 2 sqrt(r^2 - x^2)

(Beer-Lambert: absorption is the chord length through the lumen times the
attenuation, convolved with the detector blur; a linear background.)
Display-processed images are often edge-enhanced (an unsharp mask
``y + g (y - G_s * y)``); across a straight vessel that mask turns the template
into ``(1 + g) T_r - g G_s * T_r``, and G_s * T_r is the same template at blur
sqrt(blur^2 + s^2) (Gaussians compose), so the enhanced model is one more table
(``enhance = (g, s)``). For every
radius of a table the least-squares c0, c1, b come from a precomputed
pseudo-inverse, so a whole trace of profiles is fitted by two matrix products;
the radius is the table's RSS minimum refined by a parabola (as in the
model-based QCA of Sonka et al., IEEE TMI 1995, and Fessler & Macovski's
parametric cylinder fits, 1991).

Profile windows, shift searches and radius tables follow the vessel's size, so a
35 px wide left main fits as well as a 2 px wide distal branch.

Pixels are (col, row), 0-based.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage as ndi

__all__ = [
    "ProfileFit",
    "profile_table",
    "fit_profiles",
    "fit_along",
    "sample_profiles",
    "sample_along",
    "SampledProfiles",
    "spline_coefficients",
    "half_width_for",
    "max_shift_for",
    "parabola_vertex_offset",
    "MIN_MAX_SHIFT_PX",
]

FloatArray = NDArray[np.float64]

#: Smallest radius of the tables (px).
_R_MIN_PX = 0.3
#: Half-width classes (px) of the profile windows (a few, so tables are reused).
_HALF_WIDTHS_PX = (5.0, 6.0, 7.0, 8.0, 9.5, 11.0, 13.0, 15.0, 17.5, 20.0, 23.0, 26.0,
                   30.0, 35.0, 41.0, 48.0)
#: Shift search (px, each way) along the normal for small vessels; larger vessels
#: search a quarter of the window's half-width.
MIN_MAX_SHIFT_PX = 2.0


def parabola_vertex_offset(f0: NDArray, f1: NDArray, f2: NDArray,
                           limit: float = 0.5) -> NDArray:
    """Offset in [-limit, limit] samples of the vertex of the parabola through three
    equally spaced values around a discrete minimum (0 where it is not convex)."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        denom = f0 - 2.0 * f1 + f2
        delta = np.where(np.isfinite(denom) & (denom > 0), 0.5 * (f0 - f2) / denom, 0.0)
        return np.minimum(np.maximum(delta, -limit), limit)  # never NaN: finite / positive


def half_width_for(radius_px: float) -> float:
    """Profile half-width (px) used for a vessel of about ``radius_px``: the edges plus
    ~3 blur widths, but no farther (a wider window lets a neighbour pull the fit)."""
    need = 1.3 * float(radius_px) + 3.0
    for c in _HALF_WIDTHS_PX:
        if c >= need:
            return c
    return _HALF_WIDTHS_PX[-1]


def max_shift_for(half_width_px: float) -> float:
    """Largest shift (px) searched along the normal with a window of that half-width."""
    return max(MIN_MAX_SHIFT_PX, 0.25 * float(half_width_px) - 1.0)


def _sample_step_for(half_width_px: float) -> float:
    return max(0.5, float(half_width_px) / 30.0)


def _offsets_for(half_width_px: float) -> FloatArray:
    """Sample offsets (L,) px across the vessel of a window of that half-width."""
    step = _sample_step_for(half_width_px)
    n_half = int(round(half_width_px / step))
    return np.arange(-n_half, n_half + 1) * step


@lru_cache(maxsize=32)
def _chords(r_max: float, r_step: float) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """The table's radii (R,), a fine grid of offsets x (F,) px, the chords
    2 sqrt(r^2 - x^2) (R, F) on it, and the grid's step (px)."""
    radii = np.arange(_R_MIN_PX, r_max + 0.5 * r_step, r_step)
    fine_step = 0.02 * max(1.0, r_max / 10.0)
    fine = np.arange(-r_max - 0.5, r_max + 0.5 + fine_step, fine_step)
    chord = 2.0 * np.sqrt(np.clip(radii[:, None] ** 2 - fine[None, :] ** 2, 0.0, None))
    return radii, fine, chord, fine_step


@lru_cache(maxsize=256)
def _template(half_width_px: float, sigma_px: float, r_max: float,
              r_step: float) -> FloatArray:
    """Chords of :func:`_chords` convolved with a Gaussian of ``sigma_px`` (floored at
    half the fine step) and sampled at the window's offsets: (R, L), by quadrature
    (one matrix product)."""
    chord, fine_step = _chords(r_max, r_step)[2:]
    return chord @ _window_weights(half_width_px, max(sigma_px, 0.5 * fine_step), r_max, r_step)


@lru_cache(maxsize=4)
def _window_weights(half_width_px: float, sigma_px: float, r_max: float,
                    r_step: float) -> FloatArray:
    """The quadrature weights (F, L) of :func:`_gaussian_weights` on the grid of
    :func:`_chords` at the window's offsets (a template and its chord variance at one
    blur share them)."""
    _, fine, _, fine_step = _chords(r_max, r_step)
    return _gaussian_weights(fine, _offsets_for(half_width_px), sigma_px, fine_step)


@lru_cache(maxsize=64)
def profile_table(
    half_width_px: float, blur_px: float, r_max: float, r_step: float,
    enhance: tuple[float, float] = (0.0, 0.0),
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Least-squares tables for the blurred-cylinder profile model (module docstring).

    ``enhance`` = (gain g, Gaussian sigma s px) of an edge-enhancing unsharp mask
    (g = 0: none).

    Returns
    -------
    offsets : (L,) sample offsets (px) across the vessel.
    radii : (R,) radii (px) of the table.
    design_flat : (L, 3R) the design matrices D_r side by side.
    pinv_flat : (L, 3R) the pseudo-inverses (D_r^T D_r)^-1 D_r^T, transposed, side by side.
    """
    offsets = _offsets_for(half_width_px)
    radii = _chords(r_max, r_step)[0]
    # Template (R, L): the chord convolved with the Gaussian blur (cached per blur, so
    # an enhancement grid at one blur convolves each chord once per mask sigma).
    template = _template(half_width_px, blur_px, r_max, r_step)
    gain, sigma_e = enhance
    if gain > 0:
        wide = _template(half_width_px, float(np.hypot(blur_px, sigma_e)), r_max, r_step)
        template = (1.0 + gain) * template - gain * wide
    design = np.stack(
        [np.ones_like(template), np.broadcast_to(offsets, template.shape), template], axis=1
    )  # (R, 3, L)
    gram = design @ design.transpose(0, 2, 1)
    pinv = np.linalg.inv(gram) @ design  # (R, 3, L)
    n_r, n_l = len(radii), len(offsets)
    design_flat = design.reshape(3 * n_r, n_l).T.copy()
    return offsets, radii, design_flat, pinv.reshape(3 * n_r, n_l).T.copy()


def _gaussian_weights(fine: FloatArray, offsets: FloatArray, sigma_px: float,
                      fine_step: float) -> FloatArray:
    """Quadrature weights (F, L) of a Gaussian of ``sigma_px`` centred at each offset,
    on the fine grid; weights below 1e-30 are exact zeros (subnormal numbers would
    slow the matrix products a hundredfold)."""
    z = (offsets[None, :] - fine[:, None]) / sigma_px
    kernel = np.where(np.abs(z) < 12.0, np.exp(-0.5 * np.minimum(z * z, 144.0)), 0.0)
    return kernel * (fine_step / (np.sqrt(2.0 * np.pi) * sigma_px))


@lru_cache(maxsize=256)
def _chord_variance(half_width_px: float, blur_px: float, r_max: float,
                    r_step: float) -> FloatArray:
    """V = G * C^2 - (G * C)^2 (R, L) of :func:`_blur_variance_table` (no enhancement in
    it; G * C is the template of :func:`_template`)."""
    chord, fine_step = _chords(r_max, r_step)[2:]
    kernel = _window_weights(half_width_px, max(blur_px, 0.5 * fine_step), r_max, r_step)
    mean = _template(half_width_px, blur_px, r_max, r_step)
    return np.maximum((chord**2) @ kernel - mean**2, 0.0)


@lru_cache(maxsize=64)
def _blur_variance_table(
    half_width_px: float, blur_px: float, r_max: float, r_step: float,
    enhance: tuple[float, float] = (0.0, 0.0),
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Second-order term of detector blur acting on intensity, not on absorption.

    -log(G * exp(-mu C)) = mu (G * C) - mu^2 / 2 V + O(mu^3), V = G * C^2 - (G * C)^2
    (the chord C's local variance under the blur kernel G; a cumulant expansion):
    an absorption profile is shallower at its edges than the blurred chord.

    Returns V (R, L), D_r^T V_r (R, 3), the least-squares coefficients of V_r
    (R, 3) and |V_r|^2 (R,), for the table of :func:`profile_table`.
    """
    _, radii, design_flat, pinv_flat = profile_table(half_width_px, blur_px, r_max, r_step,
                                                     enhance)
    var = _chord_variance(half_width_px, blur_px, r_max, r_step)
    n_r = len(radii)
    design = design_flat.T.reshape(n_r, 3, -1)
    pinv = pinv_flat.T.reshape(n_r, 3, -1)
    return (var, np.einsum("rkl,rl->rk", design, var), np.einsum("rkl,rl->rk", pinv, var),
            np.einsum("rl,rl->r", var, var))


def fit_profiles(
    profiles: FloatArray, half_width_px: float, blur_px: float, r_max: float, r_step: float,
    natural_scale: float | None = 1.0, enhance: tuple[float, float] = (0.0, 0.0),
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Best radius for each absorption profile by a table search over r.

    The model includes the second-order effect of blurring the intensity (see
    :func:`_blur_variance_table`): a(x) = c0 + c1 x + b T_r(x) - k b^2 / 2 V_r(x), with
    b from the first-order fit.

    Parameters
    ----------
    profiles : (M, L) absorption samples at the table's offsets.
    natural_scale : k, natural absorption units (-log of the intensity ratio) per
        unit of ``profiles``; None leaves the second-order term out.
    enhance : (gain, sigma px) of the edge enhancement (:func:`profile_table`).

    Returns
    -------
    rss : (M,) residual sum of squares of the best fit (inf if no dark vessel fits).
    radius_px : (M,) radius, refined by a parabola through the RSS minimum.
    depth : (M,) fitted attenuation b (per px of chord).
    total_ss : (M,) sum of squares of the profile about its mean.
    """
    _, radii, design_flat, pinv_flat = profile_table(half_width_px, blur_px, r_max, r_step,
                                                     enhance)
    m_prof = len(profiles)
    u = (profiles @ design_flat).reshape(m_prof, -1, 3)  # (M, R, 3)  D_r^T p
    coef = (profiles @ pinv_flat).reshape(m_prof, -1, 3)  # (M, R, 3)  least-squares c0, c1, b
    # RSS = |p|^2 - p^T D_r (D_r^T D_r)^-1 D_r^T p
    sq = np.einsum("ml,ml->m", profiles, profiles)
    projected = np.einsum("mrk,mrk->mr", u, coef)
    depth_r = coef[:, :, 2]  # (M, R)
    if natural_scale is None:
        rss = sq[:, None] - projected
    else:
        var, d_var, p_var, var_sq = _blur_variance_table(half_width_px, blur_px, r_max, r_step,
                                                         enhance)
        p_dot_var = profiles @ var.T  # (M, R)
        # p' = p + alpha V_r, alpha = k b^2 / 2 from the first-order fit: D^T p' = u + alpha
        # d_var, coefficients coef + alpha p_var, so p'^T D (D^T D)^-1 D^T p' expands as
        # u.coef + alpha (u.p_var + d_var.coef) + alpha^2 d_var.p_var (no (M, R, 3) temporaries)
        alpha = 0.5 * natural_scale * np.clip(depth_r, 0.0, None) ** 2
        cross = np.einsum("mrk,rk->mr", u, p_var) + np.einsum("mrk,rk->mr", coef, d_var)
        alpha_sq = alpha * alpha
        sq_c = sq[:, None] + 2.0 * alpha * p_dot_var + alpha_sq * var_sq[None]
        rss = sq_c - (projected + alpha * cross + alpha_sq * np.einsum("rk,rk->r", d_var, p_var))
        depth_r = depth_r + alpha * p_var[None, :, 2]
    rss = np.where(depth_r > 0, rss, np.inf)
    best = np.argmin(rss, axis=1)
    m = np.arange(m_prof)
    i = np.clip(best, 1, len(radii) - 2)
    f0, f1, f2 = rss[m, i - 1], rss[m, i], rss[m, i + 1]
    delta = parabola_vertex_offset(f0, f1, f2)
    radius = radii[i] + delta * (radii[1] - radii[0])
    radius = np.where(best == i, radius, radii[best])
    # The RSS at the parabola's vertex (not at the nearest table radius, whose
    # quantisation would dominate the RSS of a clean profile).
    with np.errstate(invalid="ignore"):
        at_vertex = f1 - 0.5 * delta * (f0 - f2) * 0.5
    rss_best = np.where((best == i) & np.isfinite(at_vertex), at_vertex, rss[m, best])
    total = sq - profiles.sum(axis=1) ** 2 / profiles.shape[1]
    return np.maximum(rss_best, 0.0), radius, depth_r[m, best], np.maximum(total, 1e-300)


def spline_coefficients(image: FloatArray) -> FloatArray:
    """Cubic B-spline coefficients (H, W) of an image, for :func:`sample_profiles` with
    ``order=3`` (Unser, "Splines: a perfect fit for signal and image processing",
    IEEE SPM 1999): cubic interpolation of a blurred vessel does not flatten its
    peak the way bilinear interpolation does (a radius bias of several % at r ~ 2 px)."""
    return ndi.spline_filter(np.asarray(image, dtype=float), order=3, mode="mirror")


def sample_profiles(
    image: FloatArray, points_px: FloatArray, normals: FloatArray, offsets: FloatArray,
    order: int = 1,
) -> FloatArray:
    """Samples (N, L) of ``image`` at points_px + offsets * normals: bilinear
    (``order=1``), or cubic B-spline (``order=3``; ``image`` holds the coefficients
    of :func:`spline_coefficients`)."""
    n, m = len(points_px), len(offsets)
    coords = np.empty((2, n, m))  # (row, col) of points_px + offsets * normals
    for k, axis in enumerate((1, 0)):
        np.multiply(offsets[None, :], normals[:, axis, None], out=coords[k])
        coords[k] += points_px[:, axis, None]
    out = ndi.map_coordinates(image, coords.reshape(2, n * m), order=order, mode="mirror",
                              prefilter=False)
    return out.reshape(n, m)


@dataclass(frozen=True)
class ProfileFit:
    """Fits at N points along a curve.

    shift_px : (N,) best centre offset along the normal.
    radius_px : (N,) fitted radius (nan where nothing fitted).
    ok : (N,) bool, a fit inside the shift search.
    rss : (N,) residual variance of the best fit (inf where nothing fitted).
    max_shift_px : (N,) the shift search's limit at each point.
    rss_fraction : (N,) RSS / total sum of squares of the profile (scale-free).
    depth : (N,) fitted attenuation b (per px of chord; 0 where nothing fitted).
    """

    shift_px: FloatArray
    radius_px: FloatArray
    ok: NDArray[np.bool_]
    rss: FloatArray
    max_shift_px: FloatArray
    rss_fraction: FloatArray
    depth: FloatArray


@dataclass(frozen=True)
class SampledProfiles:
    """Profiles sampled once at N points for repeated :func:`fit_along` calls there (a
    grid of model parameters: power, blur, enhancement), before any ``transform``.

    n_points : N.
    search_shift : whether the samples cover the shift search.
    groups : per half-width class: (half-width px, indices (S,) of its points, shifts
        (K,) px, offsets (L,) px, samples (S * K, L)).
    """

    n_points: int
    search_shift: bool
    groups: tuple[tuple[float, NDArray[np.intp], FloatArray, FloatArray, FloatArray], ...]


def sample_along(
    absorb: FloatArray, points_px: FloatArray, normals: FloatArray,
    radius_guess_px: FloatArray, *, search_shift: bool = True, order: int = 1,
) -> SampledProfiles:
    """The profiles :func:`fit_along` fits (same parameters), sampled once."""
    half = np.array([half_width_for(r) for r in radius_guess_px])
    groups = []
    for hw in np.unique(half):
        sel = np.nonzero(half == hw)[0]
        if search_shift:
            m_shift = max_shift_for(hw)
            shifts = np.arange(-m_shift, m_shift + 1e-4, max(0.5, m_shift / 4.0))
        else:
            shifts = np.array([0.0])
        offsets = _offsets_for(float(hw))
        all_offsets = (shifts[:, None] + offsets[None, :]).ravel()
        prof = sample_profiles(absorb, points_px[sel], normals[sel], all_offsets, order)
        groups.append((float(hw), sel, shifts, offsets,
                       prof.reshape(len(sel) * len(shifts), len(offsets))))
    return SampledProfiles(n_points=len(points_px), search_shift=search_shift,
                           groups=tuple(groups))


def fit_along(
    absorb: FloatArray,
    points_px: FloatArray,
    normals: FloatArray,
    radius_guess_px: FloatArray,
    blur_px: float,
    r_step: float,
    *,
    search_shift: bool = True,
    transform=None,
    order: int = 1,
    natural_scale: float | None = 1.0,
    enhance: tuple[float, float] = (0.0, 0.0),
    samples: SampledProfiles | None = None,
) -> ProfileFit:
    """Fit the cylinder model at every point, over shifts along the normal.

    Parameters
    ----------
    absorb : (H, W) image sampled (absorption, or raw values when ``transform``
        maps samples to absorption).
    points_px, normals : (N, 2) curve points (in ``absorb``'s pixels) and unit normals.
    radius_guess_px : (N,) radius guesses (choose the window and table).
    blur_px : Gaussian blur (px) of the model.
    r_step : radius table step (px) for vessels of radius ~10 px or less.
    search_shift : search shifts along the normal (else fit at the points).
    transform : optional callable applied to the sampled profiles (M, L).
    order : 1 (bilinear) or 3 (``absorb`` holds cubic spline coefficients).
    natural_scale : natural absorption units per unit of the (transformed) samples,
        for the second-order blur term (None: first-order model only).
    enhance : (gain, sigma px) of the image's edge enhancement (:func:`profile_table`).
    samples : the profiles of :func:`sample_along` with these points, normals,
        radius guesses, ``search_shift`` and ``order`` (``absorb`` is not sampled again).

    Returns
    -------
    ProfileFit; rss is the residual variance (large where the profile is not a
    single clean tube: an overlapping or touching vessel).
    """
    n = len(points_px)
    shift_out = np.zeros(n)
    radius_out = np.full(n, np.nan)
    rss_out = np.full(n, np.inf)
    frac_out = np.full(n, np.inf)
    depth_out = np.zeros(n)
    limit = np.zeros(n)
    if samples is None:
        samples = sample_along(absorb, points_px, normals, radius_guess_px,
                               search_shift=search_shift, order=order)
    elif samples.n_points != n or samples.search_shift != search_shift:
        raise ValueError(f"samples of {samples.n_points} points (search_shift "
                         f"{samples.search_shift}) for {n} points (search_shift {search_shift})")
    for hw, sel, shifts, offsets, prof in samples.groups:
        m_shift = max_shift_for(hw)
        step_r = max(r_step, hw / 100.0)
        if transform is not None:
            prof = transform(prof)
        rss, rad, dep, tot = fit_profiles(prof, hw, blur_px, hw - 1.0, step_r, natural_scale,
                                          enhance)
        rss = rss.reshape(len(sel), len(shifts))
        dep = dep.reshape(len(sel), len(shifts))
        rad = rad.reshape(len(sel), len(shifts))
        tot = tot.reshape(len(sel), len(shifts))
        k = np.argmin(rss, axis=1)
        j = np.arange(len(sel))
        shift_out[sel] = shifts[k]
        radius_out[sel] = rad[j, k]
        rss_out[sel] = rss[j, k] / (len(offsets) - 4)
        frac_out[sel] = rss[j, k] / tot[j, k]
        depth_out[sel] = np.where(np.isfinite(rss[j, k]), dep[j, k], 0.0)
        limit[sel] = m_shift
        if len(shifts) >= 3:  # parabolic refinement of the shift
            kk = np.clip(k, 1, len(shifts) - 2)
            d = parabola_vertex_offset(rss[j, kk - 1], rss[j, kk], rss[j, kk + 1])
            step = shifts[1] - shifts[0]
            shift_out[sel] = np.where(kk == k, shifts[kk] + d * step, shifts[k])
    ok = np.isfinite(rss_out) & np.isfinite(radius_out)
    if search_shift:
        ok &= np.abs(shift_out) < limit - 1e-9
    return ProfileFit(shift_px=shift_out, radius_px=radius_out, ok=ok, rss=rss_out,
                      max_shift_px=limit, rss_fraction=frac_out, depth=depth_out)
