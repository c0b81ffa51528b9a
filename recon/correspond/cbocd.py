"""CBOCD: the curvature and brightness order curve descriptor (sec. 3.3, eqs. 6-7).

Each point of a traced centerline gets an integer in {2, 3, 4, 5} that says
how likely it is to lie on an OPE (an overlapping or parallel element, where
the projection foreshortens or folds the vessel):

    5  Brightness OPE and Curvature OPE      eq. (6)
    4  Curvature OPE only
    3  Brightness OPE only
    2  other

The matcher (``recon.correspond.matching``) uses the value as the adaptive step size of
its dynamic programming (eqs. 9-10).

Brightness sign convention. The paper marks a point as Brightness OPE when
its brightness is *below* the linear trend between the two ends (eq. 7): a
vessel that runs along the ray, or overlaps itself, holds more contrast on
the pixel and so absorbs more. Our images are MONOCHROME2 with
contrast-filled vessels dark, so "more contrast" is also "lower value": the
rule applies to the raw values unchanged. For an inverted (bright-vessel)
image pass ``vessel_dark=False`` and the comparison is flipped. The paper's
raw rule (strictly below the trend) marks about half of all points on noisy
data, so a point must be below the trend by a margin, by default two robust
standard deviations of the residual brightness (MAD), and the trend line is
fitted robustly to all points rather than drawn through the two end means
(an end seen along the ray is dark and would hide itself), see
:func:`brightness_ope`.

Lengths. The trace is resampled finely (0.5 px per point or less), so the
curvature support region, the end windows of eq. (7) and the post-processing
gaps are given in pixels of arc length and converted to points from the
trace spacing (:func:`cbocd_parts`; defaults and their reasons at
``BETA_PX``). The CBOCD values themselves stay the paper's 2..5: the DP uses
them as a local slope (constructed points per standard point), which is
dimensionless because both traces have the same number of points.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "CBOCD_OTHER",
    "CBOCD_BRIGHTNESS",
    "CBOCD_CURVATURE",
    "CBOCD_BOTH",
    "brightness_ope",
    "curvature_ope",
    "postprocess_ope",
    "cbocd_descriptor",
    "cbocd_parts",
    "CbocdParts",
    "trace_spacing_px",
    "px_to_points",
]

CBOCD_OTHER = 2
CBOCD_BRIGHTNESS = 3
CBOCD_CURVATURE = 4
CBOCD_BOTH = 5

BoolArray = NDArray[np.bool_]


def _as_1d(values: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{name} must have shape (N,), got {arr.shape}")
    return arr


def _robust_sigma(residual: NDArray[np.float64]) -> float:
    """1.4826 MAD of a (N,) residual (the standard deviation for Gaussian noise)."""
    return float(1.4826 * np.median(np.abs(residual - np.median(residual))))


def _huber_line(
    x: NDArray[np.float64], y: NDArray[np.float64], start: NDArray[np.float64], iters: int = 20
) -> NDArray[np.float64]:
    """Huber IRLS straight-line fit (N,) of y on x, started from the line ``start`` (N,)."""
    fit = start
    if len(x) < 3:
        return fit
    design = np.column_stack([np.ones_like(x), x])  # (N, 2)
    for _ in range(iters):
        r = y - fit
        k = 1.345 * max(_robust_sigma(r), 1e-12)
        w = np.minimum(1.0, k / np.maximum(np.abs(r), 1e-12))  # Huber weights
        sw = np.sqrt(w)
        coef, *_ = np.linalg.lstsq(design * sw[:, None], y * sw, rcond=None)
        new = design @ coef
        if np.allclose(new, fit, atol=1e-9 * (1.0 + np.abs(y).max())):
            return new
        fit = new
    return fit


def brightness_ope(
    brightness: ArrayLike,
    *,
    n_end: int = 10,
    margin_sigma: float = 2.0,
    margin: float | None = None,
    vessel_dark: bool = True,
    trend: str = "robust",
) -> BoolArray:
    """Brightness OPE mask (eq. 7).

    InNow_i is a straight line over the point index, the contrast trend from
    the proximal to the distal end. A point is Brightness OPE when it holds
    more contrast than InNow_i, i.e. for dark vessels
    ``brightness_i < InNow_i - margin``.

    ``trend="ends"`` is the paper's line: InFirst and InLast are the mean
    brightness of the first and last ``n_end`` points. It fails exactly where
    an OPE matters most: a trace whose end runs along the ray is very dark
    over its last few pixels, so InLast is dark, the whole line is pulled
    down and nothing is flagged. ``trend="robust"`` (default) fits the same
    straight line to all points by iteratively reweighted least squares with
    Huber weights (k = 1.345 robust sigma), so that the OPE stretches, a
    minority, do not move it; the first/last ``n_end`` points then only
    serve as the starting line.

    Parameters
    ----------
    brightness : (N,) image value on the centerline, roughly uniform spacing.
    n_end : number of points averaged at each end (the paper's ten).
    margin_sigma : the default margin in robust standard deviations
        (1.4826 MAD) of the residual ``brightness - InNow``.
    margin : absolute margin in brightness units; overrides ``margin_sigma``.
        ``margin=0`` is the paper's raw rule.
    vessel_dark : True for MONOCHROME2 images with dark vessels (ours).
    trend : "robust" (default) or "ends" (the paper's InFirst/InLast line).

    Returns
    -------
    (N,) bool, True on Brightness OPE points.
    """
    b = _as_1d(brightness, "brightness")
    n = len(b)
    if n == 0:
        return np.zeros(0, dtype=bool)
    if not vessel_dark:
        b = -b
    k = max(1, min(int(n_end), n))
    in_first = b[:k].mean()  # eq. (7): InFirst
    in_last = b[n - k :].mean()  # eq. (7): InLast
    idx = np.arange(n, dtype=float)
    in_now = in_first + idx * (in_last - in_first) / max(n - 1, 1)  # eq. (7)
    if trend == "robust":
        in_now = _huber_line(idx, b, in_now)
    elif trend != "ends":
        raise ValueError(f"trend must be 'robust' or 'ends', got {trend!r}")
    residual = b - in_now
    if margin is None:  # at least a rounding error, so a flat profile flags nothing
        margin = max(margin_sigma * _robust_sigma(residual), 1e-9 * (1.0 + np.abs(b).max()))
    return residual < -float(margin)


def _block_indices(points_px: NDArray[np.float64], beta: int, alpha: int, rotation: float):
    """Merged block indices (N, 2 beta) of the beta points before/after each point.

    Returns the merged block index (block mod alpha/2, diagonally opposite
    blocks merged) and a validity mask (N, 2 beta) (False beyond the ends).
    """
    n = len(points_px)
    offsets = np.concatenate([np.arange(-beta, 0), np.arange(1, beta + 1)])  # (2 beta,)
    idx = np.arange(n)[:, None] + offsets[None, :]
    valid = (idx >= 0) & (idx < n)
    idx_c = np.clip(idx, 0, n - 1)
    vec = points_px[idx_c] - points_px[:, None, :]  # (N, 2 beta, 2)
    # Anticlockwise angle in the image seen with rows downwards: -row is "up".
    angle = np.arctan2(-vec[..., 1], vec[..., 0]) + rotation
    sector = 2.0 * np.pi / alpha
    block = np.floor(np.mod(angle, 2.0 * np.pi) / sector).astype(np.int64) % alpha
    merged = block % (alpha // 2)  # opposite blocks b and b + alpha/2 -> the smaller index
    valid &= np.linalg.norm(vec, axis=-1) > 1e-12
    return merged, valid


def _straight(points_px: NDArray[np.float64], alpha: int, beta: int, gamma: int, rotation: float):
    merged, valid = _block_indices(points_px, beta, alpha, rotation)
    n_half = alpha // 2
    # counts (N, alpha/2) of each merged block index among the valid neighbours
    onehot = (merged[..., None] == np.arange(n_half)) & valid[..., None]
    counts = onehot.sum(axis=1)
    n_valid = valid.sum(axis=1)  # 2 beta inside, fewer at the ends
    return counts.max(axis=1) >= n_valid - gamma


def curvature_ope(
    points_px: ArrayLike, *, alpha: int = 8, beta: int = 5, gamma: int = 2
) -> BoolArray:
    """Curvature OPE mask from the pixel support region (sec. 3.3.3).

    Around each point P_i the plane is cut into ``alpha`` sectors ("blocks",
    numbered anticlockwise); the ``beta`` points before and after P_i give
    the 2 beta block-index vector B_i. Diagonally opposite blocks are merged
    (index mod alpha/2), so a straight line through P_i puts all its
    neighbours in one merged block. P_i is straight when one merged index
    occurs at least ``2 beta - gamma`` times (``2 beta`` replaced by the
    number of neighbours that exist near the ends), otherwise curved. The
    test is repeated with the support region rotated by 180/alpha degrees
    (fig. 4b, a line on a sector boundary); a point is Curvature OPE only if
    both passes call it curved.

    Parameters
    ----------
    points_px : (N, 2) centerline (col, row), roughly uniform spacing.
    alpha : number of sectors (even).
    beta : neighbours taken on each side.
    gamma : tolerance: how many neighbours may fall outside the main block.

    Returns
    -------
    (N,) bool, True on Curvature OPE points.
    """
    p = np.asarray(points_px, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points_px must have shape (N, 2), got {p.shape}")
    if alpha < 2 or alpha % 2:
        raise ValueError(f"alpha must be an even number >= 2, got {alpha}")
    if beta < 1 or gamma < 0:
        raise ValueError(f"need beta >= 1 and gamma >= 0, got beta={beta}, gamma={gamma}")
    if len(p) < 2:
        return np.zeros(len(p), dtype=bool)
    straight_1 = _straight(p, alpha, beta, gamma, 0.0)
    straight_2 = _straight(p, alpha, beta, gamma, np.pi / alpha)  # rotated by 180/alpha deg
    return ~straight_1 & ~straight_2


def _runs(mask: BoolArray) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Start (inclusive) and stop (exclusive) indices of the True runs of a (N,) mask."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def _fill_gaps(mask: BoolArray, max_gap: int) -> BoolArray:
    """Set to True the gaps of at most ``max_gap`` points between two True runs."""
    starts, stops = _runs(mask)
    if len(starts) < 2 or max_gap <= 0:
        return mask.copy()
    gap_start, gap_stop = stops[:-1], starts[1:]
    short = (gap_stop - gap_start) <= max_gap
    delta = np.zeros(len(mask) + 1, dtype=np.int64)
    np.add.at(delta, gap_start[short], 1)
    np.add.at(delta, gap_stop[short], -1)
    return mask | (np.cumsum(delta[:-1]) > 0)


def _drop_short(mask: BoolArray, min_run: int) -> BoolArray:
    """Set to False the True runs shorter than ``min_run`` points."""
    starts, stops = _runs(mask)
    short = (stops - starts) < min_run
    delta = np.zeros(len(mask) + 1, dtype=np.int64)
    np.add.at(delta, starts[short], 1)
    np.add.at(delta, stops[short], -1)
    return mask & ~(np.cumsum(delta[:-1]) > 0)


def postprocess_ope(
    mask: ArrayLike, *, join_short_gap: int = 3, min_run: int = 4, join_long_gap: int = 12
) -> BoolArray:
    """Clean an OPE mask (end of sec. 3.3.3), all lengths in points.

    1. join two OPE runs separated by at most ``join_short_gap`` points;
    2. delete OPE runs shorter than ``min_run`` points;
    3. join the remaining runs separated by at most ``join_long_gap`` points.

    Gaps before the first run and after the last run are never filled.

    Parameters
    ----------
    mask : (N,) bool.

    Returns
    -------
    (N,) bool.
    """
    m = np.asarray(mask, dtype=bool)
    if m.ndim != 1:
        raise ValueError(f"mask must have shape (N,), got {m.shape}")
    m = _fill_gaps(m, join_short_gap)
    m = _drop_short(m, min_run)
    return _fill_gaps(m, join_long_gap)


# Defaults in pixels of arc length along the trace; converted to points from the
# trace spacing by :func:`cbocd_descriptor`, so the descriptor means the same
# at 0.2, 0.5 or 1 px per point (the constructed trace is resampled finer than
# the standard one). Reasons:
# - BETA_PX: half-width of the pixel support region. A vessel bend of radius R
#   spreads the chord directions of the neighbours within +-beta_px over about
#   beta_px / R rad; the merged blocks are 360/alpha deg wide, so with alpha = 8
#   a point is curved for R below about 1.3 beta_px. 10 px makes bends tighter
#   than ~13 px (a few lumen radii at our 0.39 mm pixels) curvature OPE, the
#   tight 2D turns a foreshortened 3D bend produces, and leaves ordinary
#   coronary curvature (R ~ 40-100 px) and trace noise (~0.2 px) alone.
# - GAMMA_PX: tolerance; neighbours within ~1 px of P_i have noisy directions
#   at sub-pixel spacing, so about that much arc may fall outside the block.
# - N_END_PX: eq. (7)'s "ten points" at the paper's ~0.5 px spline spacing.
# - post-processing: join gaps up to 2 px (one noisy sample), drop runs shorter
#   than 3 px (less than half a lumen diameter cannot be a foreshortened
#   stretch), then join runs closer than 10 px (one bend seen as two arcs).
BETA_PX = 10.0
GAMMA_PX = 1.0
N_END_PX = 5.0
JOIN_SHORT_GAP_PX = 2.0
MIN_RUN_PX = 3.0
JOIN_LONG_GAP_PX = 10.0


def trace_spacing_px(points_px: ArrayLike) -> float:
    """Mean arc-length spacing (px per point) of a (N, 2) trace."""
    p = np.asarray(points_px, dtype=float)
    if len(p) < 2:
        return 1.0
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum() / (len(p) - 1))


def px_to_points(length_px: float, spacing_px: float, minimum: int = 0) -> int:
    """Number of points (int >= ``minimum``) covering ``length_px`` at ``spacing_px``."""
    return max(int(minimum), int(round(float(length_px) / max(float(spacing_px), 1e-9))))


class CbocdParts(NamedTuple):
    """The pieces of one descriptor, for diagnostics and the benchmark.

    value : (N,) int CBOCD (eq. 6); brightness, curvature : (N,) bool, the
    post-processed OPE masks; spacing_px : trace spacing the px lengths were
    converted with.
    """

    value: NDArray[np.int64]
    brightness: BoolArray
    curvature: BoolArray
    spacing_px: float


def cbocd_parts(
    points_px: ArrayLike,
    brightness: ArrayLike,
    *,
    alpha: int = 8,
    beta_px: float = BETA_PX,
    gamma_px: float = GAMMA_PX,
    n_end_px: float = N_END_PX,
    margin_sigma: float = 2.0,
    vessel_dark: bool = True,
    trend: str = "robust",
    join_short_gap_px: float = JOIN_SHORT_GAP_PX,
    min_run_px: float = MIN_RUN_PX,
    join_long_gap_px: float = JOIN_LONG_GAP_PX,
) -> CbocdParts:
    """CBOCD (eq. 6) with its Brightness and Curvature OPE masks.

    All lengths are pixels of arc length, converted to points with the mean
    spacing of the trace (see the module constants for the defaults' reasons).

    Parameters
    ----------
    points_px : (N, 2) centerline (col, row), uniform arc-length spacing.
    brightness : (N,) image value on the centerline.
    alpha : sectors of the pixel support region (even), see :func:`curvature_ope`.
    beta_px : half-width of the support region (beta = beta_px / spacing points).
    gamma_px : noise tolerance (gamma = gamma_px / spacing points).
    n_end_px : arc length averaged for InFirst / InLast (eq. 7).
    margin_sigma, vessel_dark, trend : see :func:`brightness_ope`.
    join_short_gap_px, min_run_px, join_long_gap_px : see :func:`postprocess_ope`.

    Returns
    -------
    CbocdParts with value (N,) in {2, 3, 4, 5}.
    """
    p = np.asarray(points_px, dtype=float)
    b = _as_1d(brightness, "brightness")
    if p.ndim != 2 or p.shape != (len(b), 2):
        raise ValueError(f"points_px must have shape ({len(b)}, 2), got {p.shape}")
    h = trace_spacing_px(p)
    post = dict(
        join_short_gap=px_to_points(join_short_gap_px, h),
        min_run=px_to_points(min_run_px, h, 1),
        join_long_gap=px_to_points(join_long_gap_px, h),
    )
    bright = postprocess_ope(
        brightness_ope(
            b,
            n_end=px_to_points(n_end_px, h, 1),
            margin_sigma=margin_sigma,
            vessel_dark=vessel_dark,
            trend=trend,
        ),
        **post,
    )
    curved = postprocess_ope(
        curvature_ope(
            p, alpha=alpha, beta=px_to_points(beta_px, h, 1), gamma=px_to_points(gamma_px, h)
        ),
        **post,
    )
    out = np.full(len(b), CBOCD_OTHER, dtype=np.int64)  # eq. (6)
    out[bright] = CBOCD_BRIGHTNESS
    out[curved] = CBOCD_CURVATURE
    out[bright & curved] = CBOCD_BOTH
    return CbocdParts(value=out, brightness=bright, curvature=curved, spacing_px=h)


def cbocd_descriptor(points_px: ArrayLike, brightness: ArrayLike, **kwargs) -> NDArray[np.int64]:
    """CBOCD value (N,) in {2, 3, 4, 5} of each centerline point (eq. 6).

    Parameters
    ----------
    points_px : (N, 2) centerline (col, row), uniform arc-length spacing.
    brightness : (N,) image value on the centerline.
    **kwargs : the keyword parameters of :func:`cbocd_parts` (lengths in px).

    Returns
    -------
    (N,) int: 5 brightness and curvature OPE, 4 curvature only, 3 brightness
    only, 2 other.
    """
    return cbocd_parts(points_px, brightness, **kwargs).value
