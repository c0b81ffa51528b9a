"""The vessel's walls across a trace, for centring where a neighbour overlaps one side.

Where another vessel overlaps one side of the traced one in projection (a branch
running alongside, a vessel passing behind it), a single-tube profile fit spans
both and its centre moves towards the neighbour. The wall on the other side
stays where it was. :func:`one_wall_shifts` finds such places from the two
walls' offsets along the normals (:func:`wall_offsets`: the steepest rise and
fall of the absorption profile, an edge detector that assumes no profile model)
and centres the trace half a reference width inside the wall that stayed.

Offsets are px along each point's unit normal, points 1 px apart along the
trace; pixels are (col, row).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage as ndi

from recon.profile_fit import parabola_vertex_offset, sample_profiles

__all__ = ["reference_width", "wall_offsets", "one_wall_shifts"]

FloatArray = NDArray[np.float64]

#: Sample step (px) of the profiles across the vessel, and the Gaussian sigma (px)
#: of the derivative filter along them.
_STEP_PX = 0.25
_DERIVATIVE_SIGMA_PX = 0.75
#: The walls are sought up to this many guessed radii (plus 3 px) from the curve.
_REACH = 2.5
#: A wall nearer the point than this many guessed radii is not taken (nan).
_INNER = 0.3
#: Running-median window (points) of the reference width.
_WINDOW_PX = 121
#: A width more than this fraction above the reference is two vessels taken as one.
_WIDE_TOL = 0.2
#: A wall stays put within this fraction of the reference width (at least
#: _STAY_PX) of where the clean points put it; it has moved out beyond twice that.
_STAY = 0.1
_STAY_PX = 0.75
#: A fit is pulled off its walls' midpoint beyond this many robust standard
#: deviations of the trace's fits about their midpoints, and at least this far (px).
_PULL_SD = 4.0
_PULL_PX = 0.75


def wall_offsets(absorb: FloatArray, points_px: FloatArray, normals: FloatArray,
                 radius_guess_px: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Offsets (N,), (N,) of the left and right walls: the steepest rise of the
    absorption profile (vessel bright) on the negative side of each point and the
    steepest fall on the positive side, to a fraction of a sample (parabola); nan
    where that slope is at the end of the side searched or within :data:`_INNER`
    guessed radii of the point.

    absorb : (H, W) absorption image; points_px, normals : (N, 2); radius_guess_px : (N,).
    """
    reach = _REACH * float(np.max(radius_guess_px)) + 3.0
    offsets = np.arange(-reach, reach + 1e-9, _STEP_PX)
    prof = sample_profiles(absorb, points_px, normals, offsets)
    grad = ndi.gaussian_filter1d(prof, _DERIVATIVE_SIGMA_PX / _STEP_PX, axis=1, order=1)
    limit = (_REACH * radius_guess_px + 3.0)[:, None]
    left_side = (offsets[None, :] <= 0.0) & (offsets[None, :] >= -limit)
    right_side = (offsets[None, :] >= 0.0) & (offsets[None, :] <= limit)
    k_left = np.argmax(np.where(left_side, grad, -np.inf), axis=1)
    k_right = np.argmin(np.where(right_side, grad, np.inf), axis=1)
    left, right = _refine(grad, k_left, offsets), _refine(-grad, k_right, offsets)
    # No wall where the profile does not rise (fall), where the steepest slope is at
    # the end of the side searched, or near the point.
    inner = _INNER * radius_guess_px
    lim = limit[:, 0] - _STEP_PX
    rows = np.arange(len(points_px))
    left = np.where((grad[rows, k_left] <= 0) | (left > -inner) | (left < -lim), np.nan, left)
    right = np.where((grad[rows, k_right] >= 0) | (right < inner) | (right > lim), np.nan,
                     right)
    return left, right


def _refine(g: FloatArray, k: NDArray[np.intp], offsets: FloatArray) -> FloatArray:
    """Offsets (N,) of the maxima of the rows of g (N, L) near columns k, by a parabola."""
    rows = np.arange(len(k))
    kk = np.clip(k, 1, g.shape[1] - 2)
    d = parabola_vertex_offset(-g[rows, kk - 1], -g[rows, kk], -g[rows, kk + 1])
    return offsets[kk] + np.where(kk == k, d, 0.0) * _STEP_PX


def reference_width(width_px: FloatArray, fitted: NDArray[np.bool_]) -> FloatArray:
    """The running reference width (N,): the median over :data:`_WINDOW_PX` points
    of the fitted widths, capped by their robust linear trend along the trace
    (Tukey's biweight on log width) plus 2.5 robust standard deviations (at least
    5 %), so that
    an overlap longer than half the window still stands out (a straight trend: a
    curved one could follow an overlap in the middle of the trace)."""
    idx = np.arange(len(width_px))
    good = fitted & np.isfinite(width_px) & (width_px > 0)
    if not np.any(good):
        return np.full(len(width_px), np.nan)
    w_all = np.interp(idx, idx[good], width_px[good])
    n_win = max(_WINDOW_PX | 1, 3)
    w_med = ndi.median_filter(w_all, size=n_win, mode="nearest")
    if int(good.sum()) < 3 * n_win // 2:
        return w_med
    t = idx / max(len(idx) - 1, 1)
    design = np.column_stack([np.ones_like(t), t])
    y = np.log(width_px[good])
    coef = np.array([float(np.median(y)), 0.0])  # a start the majority of points holds
    sd = 0.02
    for _ in range(6):
        resid = y - design[good] @ coef
        sd = max(1.4826 * float(np.median(np.abs(resid))), 0.02)
        u = resid / (4.685 * sd)  # Tukey's biweight constant (95 % efficiency)
        weight = np.sqrt(np.where(np.abs(u) < 1.0, (1.0 - u**2) ** 2, 0.0))
        coef = np.linalg.lstsq(design[good] * weight[:, None], y * weight, rcond=None)[0]
    trend = np.exp(design @ coef)
    return np.minimum(w_med, trend * np.exp(2.5 * sd))


def one_wall_shifts(shift_px: FloatArray, left_px: FloatArray, right_px: FloatArray,
                    fitted: NDArray[np.bool_]) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Shifts (N,) from the walls where a neighbour pulls the profile fit, and where (N,).

    - Walls a normal width apart (within :data:`_WIDE_TOL` of :func:`reference_width`)
      but a fit whose centre is off their midpoint by more than
      :data:`_PULL_SD` robust standard deviations (at least :data:`_PULL_PX`): the
      neighbour lies inside the fit's window, beyond the wall. The centre is the
      midpoint.
    - Walls wider apart than the reference because one moved out and the other did
      not: the centre is half a reference width inside the wall that stayed.
    Both carry the median offset of the fits from the midpoint (a profile fit and the
    steepest slopes need not agree exactly). Elsewhere the fits' shifts stand.

    shift_px : (N,) the profile fits' centres; left_px, right_px : (N,) the walls
    (:func:`wall_offsets`); fitted : (N,) where the fits and walls count.
    """
    width = right_px - left_px
    ok = fitted & np.isfinite(width) & (width > 0) & np.isfinite(shift_px)
    done = np.zeros(len(shift_px), dtype=bool)
    if int(ok.sum()) < 3:
        return shift_px, done
    w_ref = reference_width(width, ok)
    wide = ok & (width > (1.0 + _WIDE_TOL) * w_ref)
    normal = ok & ~wide & (width >= (1.0 - _WIDE_TOL) * w_ref)
    if int(normal.sum()) < 3:
        return shift_px, done
    mid = 0.5 * (left_px + right_px)
    off = shift_px - mid
    bias = float(np.median(off[normal]))
    sd = 1.4826 * float(np.median(np.abs(off[normal] - bias)))
    pulled = normal & (np.abs(off - bias) > max(_PULL_PX, _PULL_SD * sd))
    new = shift_px.copy()
    new[pulled] = mid[pulled] + bias
    idx = np.arange(len(shift_px))
    clean = normal & ~pulled
    expect_l = np.interp(idx, idx[clean], left_px[clean])
    expect_r = np.interp(idx, idx[clean], right_px[clean])
    tol = np.maximum(_STAY_PX, _STAY * w_ref)
    out_l, out_r = expect_l - left_px, right_px - expect_r  # > 0: that wall moved out
    keep_r = wide & (np.abs(out_r) <= tol) & (out_l > 2.0 * tol)
    keep_l = wide & (np.abs(out_l) <= tol) & (out_r > 2.0 * tol)
    new[keep_r] = right_px[keep_r] - 0.5 * w_ref[keep_r] + bias
    new[keep_l] = left_px[keep_l] + 0.5 * w_ref[keep_l] + bias
    done = pulled | keep_r | keep_l
    return new, done

