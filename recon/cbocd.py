"""CBOCD: the curvature and brightness order curve descriptor (sec. 3.3, eqs. 6-7).

Each point of a traced centerline gets an integer in {2, 3, 4, 5} that says
how likely it is to lie on an OPE (an overlapping or parallel element, where
the projection foreshortens or folds the vessel):

    5  Brightness OPE and Curvature OPE      eq. (6)
    4  Curvature OPE only
    3  Brightness OPE only
    2  other

The matcher (``recon.matching``) uses the value as the adaptive step size of
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
standard deviations of the residual brightness (MAD), see
:func:`brightness_ope`.
"""

from __future__ import annotations

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


def brightness_ope(
    brightness: ArrayLike,
    *,
    n_end: int = 10,
    margin_sigma: float = 2.0,
    margin: float | None = None,
    vessel_dark: bool = True,
) -> BoolArray:
    """Brightness OPE mask (eq. 7).

    InFirst and InLast are the mean brightness of the first and last
    ``n_end`` points; InNow_i is the straight line between them over the
    point index. A point is Brightness OPE when it holds more contrast than
    InNow_i, i.e. for dark vessels ``brightness_i < InNow_i - margin``.

    Parameters
    ----------
    brightness : (N,) image value on the centerline, roughly uniform spacing.
    n_end : number of points averaged at each end (the paper's ten).
    margin_sigma : the default margin in robust standard deviations
        (1.4826 MAD) of the residual ``brightness - InNow``.
    margin : absolute margin in brightness units; overrides ``margin_sigma``.
        ``margin=0`` is the paper's raw rule.
    vessel_dark : True for MONOCHROME2 images with dark vessels (ours).

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
    in_now = in_first + np.arange(n) * (in_last - in_first) / max(n - 1, 1)  # eq. (7)
    residual = b - in_now
    if margin is None:
        mad = np.median(np.abs(residual - np.median(residual)))
        margin = margin_sigma * 1.4826 * mad
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


def cbocd_descriptor(
    points_px: ArrayLike,
    brightness: ArrayLike,
    *,
    alpha: int = 8,
    beta: int = 5,
    gamma: int = 2,
    n_end: int = 10,
    margin_sigma: float = 2.0,
    vessel_dark: bool = True,
    join_short_gap: int = 3,
    min_run: int = 4,
    join_long_gap: int = 12,
) -> NDArray[np.int64]:
    """CBOCD value (N,) in {2, 3, 4, 5} of each centerline point (eq. 6).

    Parameters
    ----------
    points_px : (N, 2) centerline (col, row), uniform arc-length spacing.
    brightness : (N,) image value on the centerline.
    alpha, beta, gamma : see :func:`curvature_ope`.
    n_end, margin_sigma, vessel_dark : see :func:`brightness_ope`.
    join_short_gap, min_run, join_long_gap : see :func:`postprocess_ope`,
        applied to both masks.

    Returns
    -------
    (N,) int: 5 brightness and curvature OPE, 4 curvature only, 3 brightness
    only, 2 other.
    """
    p = np.asarray(points_px, dtype=float)
    b = _as_1d(brightness, "brightness")
    if p.ndim != 2 or p.shape != (len(b), 2):
        raise ValueError(f"points_px must have shape ({len(b)}, 2), got {p.shape}")
    post = dict(join_short_gap=join_short_gap, min_run=min_run, join_long_gap=join_long_gap)
    bright = postprocess_ope(
        brightness_ope(b, n_end=n_end, margin_sigma=margin_sigma, vessel_dark=vessel_dark),
        **post,
    )
    curved = postprocess_ope(curvature_ope(p, alpha=alpha, beta=beta, gamma=gamma), **post)
    out = np.full(len(b), CBOCD_OTHER, dtype=np.int64)  # eq. (6)
    out[bright] = CBOCD_BRIGHTNESS
    out[curved] = CBOCD_CURVATURE
    out[bright & curved] = CBOCD_BOTH
    return out
