"""Point correspondence between two traced centerlines (secs. 3.3.1, 3.4; eqs. 8-10).

The longer trace is the *standard* image, the shorter one the *constructed*
image (sec. 3.3.1); both are resampled by their splines to the same number
N of points of uniform arc length. COST (N, N) holds the distance in the
constructed image from each constructed point j to the epipolar line of
standard point i (eq. 8). The matchers compared in the paper's Table 3:

    match1  pair by point order (i <-> i)
    match2  dynamic programming with a fixed step (all steps 2)
    match3  dynamic programming with the CBOCD adaptive step (the paper's method)
    match4  epipolar constraint alone: each i takes the nearest crossing
            argmin_j COST[i, j], with no order constraint

Dynamic programming (eqs. 9-10, fig. 5), as implemented by :func:`dp_match`:

* a path goes from (0, 0) to (N_s - 1, N_c - 1): both segment ends are
  pinned (the clinician clicked corresponding ends). The paper's free first
  row (TOTAL[0, j] = COST[0, j]) is therefore reduced to TOTAL[0, 0].
* from [i-1, j'] the next pair is [i, j' + m] with m in {0, 1, ..., CBOCD_{i-1}}
  (eq. 10: TOTAL[i, j] = min(TOTAL[i-1, j], ..., TOTAL[i-1, j-m]) + COST[i, j],
  m = CBOCD_{i-1} of the standard image). Eq. (9) writes the range as the
  open interval (0, CBOCD_i); taken literally (m in {1}) it would force the
  diagonal on an N x N matrix, so we follow eq. (10)'s inclusive range. With
  the fixed step 2 (match2) the local slope is 0, 1 or 2.
* units: both traces have N points, so a step m is a local slope, the ratio
  of the two views' local stretch of the vessel (after normalising both to
  the same length), and needs no conversion to pixels. Fixed step 2 follows
  ratios within [1/2, 2]; CBOCD raises the bound to 3..5 on OPE points of the
  standard image (forward steps) and of the constructed image (repeats).
* exceptional case: m = 0 repeats column j; once j has been repeated
  CBOCD_j - 1 times (i.e. matched to CBOCD_j consecutive standard points,
  CBOCD_j of the constructed image) m = 0 is no longer allowed. The paper's
  first-column rule (TOTAL[i, 0] for i < CBOCD_0) is this same rule at j = 0.
  Rather than a single auxiliary "repeat count" matrix, which makes the
  recursion greedy, we keep one TOTAL layer per run length r = 1..max CBOCD
  (an exact DP on the state (i, j, r)).

Narrowing term (our addition, ``narrowing_weight_px``): where the vessel
runs nearly along the epipolar lines, eq. (8) hardly changes along it, and a
calibration error of a fraction of a degree slides the correspondence along
the vessel by millimetres. A stenosis narrows the lumen in both views at the
same place, so when both traces show a narrowing of at least
``NARROWING_MIN`` the DP's cost gets w |n_std(i) - n_con(j)|, with n the
narrowing profile of each trace (:func:`narrowing_profile`) scaled to a peak
of 1 so that dips of different depth still align (its effect is measured
in docs/benchmarks.md).

Sub-pixel refinement (our addition, ``subpixel=True``): the DP picks a
discrete point j; each matched pair is then moved to the crossing of the
epipolar line with the constructed polyline next to j (segments j-1..j+1),
when there is one. This removes the half-spacing quantisation along the
curve without changing which branch of the vessel was chosen.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from recon.correspond.cbocd import BETA_PX, GAMMA_PX, cbocd_descriptor
from recon.errors import CoronaryError
from recon.geometry import ViewGeometry, epipolar_lines, point_line_distance_px
from recon.types import Centerline2D, Matching

__all__ = [
    "MATCHERS",
    "MAX_POINTS",
    "DeviationPairs",
    "MatchingError",
    "cost_matrix",
    "dp_match",
    "deviation_pairs",
    "match_centerlines",
    "narrowing_profile",
]

MATCHERS = ("match1", "match2", "match3", "match4")
MAX_POINTS = 1000  # the DP is O(N^2) in memory: both traces are resampled to at most this
FIXED_STEP = 2  # match2's step (CBOCD "other")
NARROWING_WEIGHT_PX = 10.0  # px of COST per unit of (normalised) narrowing difference; ours
NARROWING_FIT_ITERATIONS = 5
NARROWING_MIN = 0.2  # the term is used only when both traces narrow at least this much

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class MatchingError(CoronaryError):
    """Matching cannot be done on these inputs; the message says why."""


class DeviationPairs(NamedTuple):
    """Deviation point pairs of sec. 3.4.2, in standard/constructed order.

    index_standard, index_constructed : (K,) row i and its argmin column j.
    points_standard_px, points_constructed_px : (K, 2) the pixels P_i, Q_j.
    row_min_px : (K,) their COST (distance to the epipolar line).
    max_row_min_px : MAX, the largest row minimum of the whole COST.
    """

    index_standard: IntArray
    index_constructed: IntArray
    points_standard_px: FloatArray
    points_constructed_px: FloatArray
    row_min_px: FloatArray
    max_row_min_px: float


# ------------------------------------------------------------------- COST
def cost_matrix(
    points_standard_px: ArrayLike,
    points_constructed_px: ArrayLike,
    view_standard: ViewGeometry,
    view_constructed: ViewGeometry,
) -> FloatArray:
    """COST matrix (N_s, N_c) of eq. (8).

    COST[i, j] is the distance in pixels, in the constructed image, from the
    constructed point j to the epipolar line of the standard point i.

    Parameters
    ----------
    points_standard_px : (N_s, 2) standard-image centerline (col, row).
    points_constructed_px : (N_c, 2) constructed-image centerline.
    view_standard, view_constructed : the two (calibrated) views.
    """
    lines = epipolar_lines(points_standard_px, view_standard, view_constructed)  # (N_s, 3)
    return point_line_distance_px(lines, points_constructed_px)  # eq. (8)


# --------------------------------------------------------------------- DP
def dp_match(
    cost: ArrayLike, steps_standard: ArrayLike, steps_constructed: ArrayLike
) -> IntArray:
    """Adaptive-step dynamic programming of eqs. (9)-(10) with both ends pinned.

    Parameters
    ----------
    cost : (N_s, N_c) COST, rows the standard image, columns the constructed.
    steps_standard : (N_s,) int >= 1, CBOCD of the standard points: from row
        i-1 the column may advance by 0..steps_standard[i-1].
    steps_constructed : (N_c,) int >= 1, CBOCD of the constructed points:
        column j may be matched to at most steps_constructed[j] consecutive
        rows (repeated steps_constructed[j] - 1 times).

    Returns
    -------
    (N_s,) int, the column j matched to each row i; j[0] = 0, j[-1] = N_c - 1,
    non-decreasing.

    Raises
    ------
    MatchingError if no path satisfies the steps (e.g. N_c far larger than
    N_s times the largest step).
    """
    C = np.asarray(cost, dtype=float)
    if C.ndim != 2 or min(C.shape) < 1:
        raise ValueError(f"cost must be a non-empty (N_s, N_c) matrix, got {C.shape}")
    ns, nc = C.shape
    s_std = np.asarray(steps_standard, dtype=np.int64).reshape(-1)
    s_con = np.asarray(steps_constructed, dtype=np.int64).reshape(-1)
    if s_std.shape != (ns,) or s_con.shape != (nc,):
        raise ValueError(
            f"steps must have shapes ({ns},) and ({nc},), got {s_std.shape} and {s_con.shape}"
        )
    if np.any(s_std < 1) or np.any(s_con < 1):
        raise ValueError("steps must be >= 1")
    if not np.all(np.isfinite(C)):
        raise ValueError("cost must be finite")
    r_max = int(s_con.max())
    big = np.inf

    # Run-length layers: total[r, j] = best cost of a path reaching (i, j) with
    # column j used by the last r + 1 rows; layers r >= CBOCD_j are forbidden.
    # Only two (N_s, N_c) tables are kept for the backtracking: the row minima
    # over the layers (TOTAL of the paper) and layer 0 (runs that start here);
    # the precursors (MATCH of the paper) are recomputed from them along the
    # path, which is cheaper than an argmin per row.
    forbidden = np.where(np.arange(1, r_max)[:, None] < s_con[None, :], 0.0, big)
    total = np.full((r_max, nc), big)
    total[0, 0] = C[0, 0]  # both ends pinned: the path starts at (0, 0)
    new = np.empty_like(total)
    row_min = np.empty((ns, nc))  # TOTAL[i, j] = min over the layers
    layer0 = np.empty((ns, nc))
    layer0[0] = total[0]
    m_max = int(s_std.max())
    padded = np.full(nc + m_max, big)
    window = np.empty(nc)
    for i in range(1, ns):
        np.minimum.reduce(total, axis=0, out=row_min[i - 1])
        padded[m_max:] = row_min[i - 1]
        step = int(s_std[i - 1])
        np.copyto(window, padded[m_max - 1 : m_max - 1 + nc])  # m = 1
        for m in range(2, step + 1):  # eq. (10): min over TOTAL[i-1, j-m], m <= CBOCD_{i-1}
            np.minimum(window, padded[m_max - m : m_max - m + nc], out=window)
        np.add(window, C[i], out=new[0])  # a new column (m >= 1)
        if r_max > 1:  # m = 0: repeat column j, at most CBOCD_j rows (exceptional case)
            np.add(total[:-1], C[i], out=new[1:])
            new[1:] += forbidden
        layer0[i] = new[0]
        total, new = new, total
    row_min[ns - 1] = total.min(axis=0)

    if not np.isfinite(row_min[ns - 1, nc - 1]):
        raise MatchingError(
            f"no monotone path from (0, 0) to ({ns - 1}, {nc - 1}) with these steps"
        )
    out = np.empty(ns, dtype=np.int64)
    j = nc - 1
    r = int(total[:, j].argmin())
    for i in range(ns - 1, 0, -1):  # backtracking (i, j) <- (i - 1, MATCH[i, j])
        out[i] = j
        if r > 0:
            r -= 1
            continue
        m_top = min(int(s_std[i - 1]), j)
        prev = row_min[i - 1, j - m_top : j][::-1]  # m = 1..m_top
        j -= int(prev.argmin()) + 1
        r = _run_layer(C, layer0, row_min[i - 1, j], i - 1, j, int(s_con[j]))
    out[0] = j
    return out


def _run_layer(
    C: FloatArray, layer0: FloatArray, target: float, i: int, j: int, max_run: int
) -> int:
    """The run-length layer r of (i, j) whose TOTAL equals ``target`` (the row minimum).

    TOTAL[i, r, j] = layer0[i - r, j] + COST[i - r + 1, j] + ... + COST[i, j], summed in
    the order of the forward pass so the values are bitwise identical.
    """
    value = float(layer0[i, j])
    if value == target:
        return 0
    for r in range(1, min(max_run - 1, i) + 1):
        value = float(layer0[i - r, j])
        for k in range(i - r + 1, i + 1):
            value += float(C[k, j])
        if value == target:
            return r
    raise AssertionError("dp_match: inconsistent backtracking")  # pragma: no cover


# -------------------------------------------------------------- deviation
def deviation_pairs(
    cost: ArrayLike,
    points_standard_px: ArrayLike,
    points_constructed_px: ArrayLike,
    threshold_px: float,
) -> DeviationPairs:
    """Deviation point pairs of sec. 3.4.2.

    MIN_i is the minimum of row i of COST (how close the epipolar line of
    P_i comes to the constructed vessel); MAX is the largest MIN_i. Rows
    whose MIN_i exceeds the threshold STD are deviation pairs (P_i, Q_j),
    j = argmin_j COST[i, j]: their epipolar line misses the vessel, and the
    calibration can use them as extra corresponding features.

    Parameters
    ----------
    cost : (N_s, N_c) COST of eq. (8).
    points_standard_px : (N_s, 2); points_constructed_px : (N_c, 2).
    threshold_px : STD in pixels.
    """
    C = np.asarray(cost, dtype=float)
    ps = np.asarray(points_standard_px, dtype=float)
    pc = np.asarray(points_constructed_px, dtype=float)
    if C.ndim != 2 or ps.shape != (C.shape[0], 2) or pc.shape != (C.shape[1], 2):
        raise ValueError(
            f"shape mismatch: cost {C.shape}, standard {ps.shape}, constructed {pc.shape}"
        )
    j_min = C.argmin(axis=1)
    row_min = C[np.arange(len(C)), j_min]  # MIN_i
    rows = np.flatnonzero(row_min > threshold_px)
    return DeviationPairs(
        index_standard=rows.astype(np.int64),
        index_constructed=j_min[rows].astype(np.int64),
        points_standard_px=ps[rows],
        points_constructed_px=pc[j_min[rows]],
        row_min_px=row_min[rows],
        max_row_min_px=float(row_min.max()),  # MAX
    )


# --------------------------------------------------------------- matching
def _refine_subpixel(
    lines: FloatArray, points_constructed_px: FloatArray, j: IntArray
) -> FloatArray:
    """Move each matched constructed point to the nearest epipolar crossing.

    lines : (K, 3) normalised epipolar lines of the matched standard points;
    points_constructed_px : (N_c, 2); j : (K,) matched indices. Returns (K, 2).
    """
    pc = points_constructed_px
    nc = len(pc)
    out = pc[j].copy()
    best = np.full(len(j), np.inf)
    d0 = np.einsum("kd,kd->k", lines[:, :2], pc[j]) + lines[:, 2]
    for side in (-1, 1):  # the segment before and after j
        k = np.clip(j + side, 0, nc - 1)
        dk = np.einsum("kd,kd->k", lines[:, :2], pc[k]) + lines[:, 2]
        cross = (k != j) & (d0 * dk <= 0) & (d0 != dk)
        t = np.where(cross, d0 / np.where(d0 != dk, d0 - dk, 1.0), 0.0)  # in [0, 1] from j
        better = cross & (t < best)
        out[better] = pc[j[better]] + t[better, None] * (pc[k[better]] - pc[j[better]])
        best[better] = t[better]
    return out


def narrowing_profile(radius_px: ArrayLike) -> FloatArray:
    """Relative narrowing (N,) in [0, 1] along a trace of uniform arc length: 1 - r / ref.

    ref is a straight line through the radii (N,) fitted robustly: points
    narrower than 0.9 ref (a lesion) or wider than 1.3 ref (an overlap) are
    left out and the fit repeated. Only narrowing counts (widening is clipped
    to 0): a stenosis narrows the lumen in both views at the same place, while
    an overlap widens it in one view only.
    """
    r = np.asarray(radius_px, dtype=float)
    x = np.arange(len(r), dtype=float)
    keep = np.isfinite(r) & (r > 0)
    if np.count_nonzero(keep) < 4:
        return np.zeros(len(r))
    for _ in range(NARROWING_FIT_ITERATIONS):
        ref = np.polyval(np.polyfit(x[keep], r[keep], 1), x)
        new_keep = np.isfinite(r) & (r > 0.9 * ref) & (r < 1.3 * ref)
        if np.count_nonzero(new_keep) < max(4, len(r) // 3) or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    return np.clip(1.0 - r / np.maximum(ref, 1e-9), 0.0, 1.0)


def match_centerlines(
    cl_a: Centerline2D,
    cl_b: Centerline2D,
    view_a: ViewGeometry,
    view_b: ViewGeometry,
    *,
    method: str = "match3",
    threshold_px: float = 2.0,
    alpha: int = 8,
    beta_px: float = BETA_PX,
    gamma_px: float = GAMMA_PX,
    cbocd_options: Mapping[str, Any] | None = None,
    subpixel: bool = True,
    max_points: int = MAX_POINTS,
    narrowing_weight_px: float = NARROWING_WEIGHT_PX,
) -> Matching:
    """Match two traced centerlines point by point (secs. 3.3.1, 3.4).

    Parameters
    ----------
    cl_a, cl_b : centerlines of one segment in view A / view B, proximal first.
    view_a, view_b : the views (view B calibrated).
    method : one of :data:`MATCHERS`.
    threshold_px : STD of sec. 3.4.2 for the deviation pairs.
    alpha, beta_px, gamma_px : CBOCD curvature parameters (match3): sectors,
        support half-width and noise tolerance in px of arc length
        (:func:`recon.correspond.cbocd.cbocd_parts`).
    cbocd_options : further keyword parameters of :func:`recon.correspond.cbocd.cbocd_parts`
        (e.g. ``margin_sigma``, ``min_run_px``).
    subpixel : move matched points to the exact epipolar crossing (match2-4).
    max_points : cap on N (both traces are resampled to N points).
    narrowing_weight_px : weight of the narrowing term added to COST for the
        dynamic programming (match2, match3; see :func:`narrowing_profile`);
        0 gives the paper's eq. (8) alone. The deviation pairs and match4 use
        eq. (8) alone in any case.

    Returns
    -------
    Matching in A/B order; ``centerline_a`` / ``centerline_b`` are the
    resampled centerlines that ``index_a`` / ``index_b`` point into.
    """
    if method not in MATCHERS:
        raise ValueError(f"unknown matching method {method!r} (use one of {', '.join(MATCHERS)})")
    t0 = time.perf_counter()
    a_is_standard = cl_a.length_px >= cl_b.length_px  # sec. 3.3.1: the longer is standard
    std, con = (cl_a, cl_b) if a_is_standard else (cl_b, cl_a)
    view_std, view_con = (view_a, view_b) if a_is_standard else (view_b, view_a)
    n = int(min(max(len(std.points_px), 2), max_points))
    std = std.resample(n)
    con = con.resample(n)  # sec. 3.3.1: the constructed trace gets N points by its spline

    with np.errstate(invalid="ignore", divide="ignore"):  # checked just below
        lines = epipolar_lines(std.points_px, view_std, view_con)
        cost = point_line_distance_px(lines, con.points_px)  # eq. (8)
    if not np.all(np.isfinite(cost)):
        raise MatchingError("the epipolar distances are undefined: views A and B project "
                            "from the same place (one view paired with itself?), so no "
                            "depth can be recovered; choose two different views")
    rows = np.arange(n)
    if method == "match1":
        j = rows.copy()
    elif method == "match4":
        j = cost.argmin(axis=1)
    else:
        if method == "match2":
            steps_s = np.full(n, FIXED_STEP)
            steps_c = np.full(n, FIXED_STEP)
        else:
            kw = dict(cbocd_options or {}, alpha=alpha, beta_px=beta_px, gamma_px=gamma_px)
            steps_s = cbocd_descriptor(std.points_px, std.brightness, **kw)
            steps_c = cbocd_descriptor(con.points_px, con.brightness, **kw)
        dp_cost = cost
        if narrowing_weight_px > 0:
            n_std = narrowing_profile(std.radius_px)
            n_con = narrowing_profile(con.radius_px)
            if min(n_std.max(), n_con.max()) >= NARROWING_MIN:
                # Both views show a lesion: align the dips by shape, whatever each one's depth.
                n_std, n_con = n_std / n_std.max(), n_con / n_con.max()
                dp_cost = cost + narrowing_weight_px * np.abs(n_std[:, None] - n_con[None, :])
        j = dp_match(dp_cost, steps_s, steps_c)
    if subpixel and method != "match1":
        pts_con = _refine_subpixel(lines, con.points_px, j)
    else:
        pts_con = con.points_px[j]
    pts_std = std.points_px
    dev = deviation_pairs(cost, std.points_px, con.points_px, threshold_px)

    if a_is_standard:
        pa, pb, ia, ib, ca, cb = pts_std, pts_con, rows, j, std, con
        dev_a, dev_b = dev.points_standard_px, dev.points_constructed_px
    else:
        pa, pb, ia, ib, ca, cb = pts_con, pts_std, j, rows, con, std
        dev_a, dev_b = dev.points_constructed_px, dev.points_standard_px
    return Matching(
        method=method,
        points_a_px=np.asarray(pa, dtype=float),
        points_b_px=np.asarray(pb, dtype=float),
        index_a=np.asarray(ia, dtype=np.int64),
        index_b=np.asarray(ib, dtype=np.int64),
        centerline_a=ca,
        centerline_b=cb,
        standard_view="a" if a_is_standard else "b",
        deviation_a_px=np.asarray(dev_a, dtype=float).reshape(-1, 2),
        deviation_b_px=np.asarray(dev_b, dtype=float).reshape(-1, 2),
        max_row_min_cost_px=dev.max_row_min_px,
        threshold_px=float(threshold_px),
        elapsed_ms=(time.perf_counter() - t0) * 1e3,
    )
