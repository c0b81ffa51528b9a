"""Move a click across the vessel onto its centre line, not along it.

Candidates are the ridge-centre pixels around the click: responding pixels whose
ridge strength is a maximum across the local vessel direction (non-maximum
suppression as in Canny 1986 / Steger, "An unbiased detector of curvilinear
structures", PAMI 1998). Each candidate q has a direction t_q, a normal n_q and a
lumen radius r_q from its scale; the click p is at ``along = |(p - q).t_q|`` and
``across = |(p - q).n_q|`` from it, and ``max(0, across - r_q)`` from its lumen.
The chosen candidate lies on the line across the vessel through the click
(along <= 1 px; at a vessel's end, within one radius), is the vessel whose
lumen holds the click (the strongest such) or else the nearest lumen, and
the snapped point is the click moved across by the candidate's offset (refined
to subpixel by a parabola through the strength across the vessel).

Pixels are (col, row), 0-based.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage as ndi

from recon.trace.trace_error import TraceError
from recon.trace.vesselness import RADIUS_PER_SIGMA, VesselnessMap

__all__ = ["snap_click", "RIDGE_LEVEL"]

FloatArray = NDArray[np.float64]

#: Ridge measure (contrast-invariant, in [0, 1]) from which a ridge-centre pixel is a
#: candidate.
RIDGE_LEVEL = 0.3


def _parabola_offset(f0: FloatArray, f1: FloatArray, f2: FloatArray) -> FloatArray:
    """Vertex offset in [-0.5, 0.5] samples of the parabola through three values
    around a discrete maximum (0 where it is not concave)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        den = f0 - 2.0 * f1 + f2
        d = np.where(np.isfinite(den) & (den < 0), 0.5 * (f0 - f2) / den, 0.0)
    return np.clip(np.nan_to_num(d), -0.5, 0.5)


def _centroid_across(ridge: NDArray, point: FloatArray, normal: FloatArray,
                     radius_px: float) -> FloatArray:
    """The point moved along ``normal`` to the centroid of the ridge measure over
    +-1 radius across the vessel (half-pixel samples; a symmetric lumen is centred
    to a fraction of a pixel where the discrete ridge maximum is not)."""
    reach = max(radius_px, 1.5)
    offs = np.arange(-reach, reach + 1e-9, 0.5)
    pos = point[None, :] + offs[:, None] * normal[None, :]
    vals = ndi.map_coordinates(ridge, [pos[:, 1], pos[:, 0]], order=1, mode="nearest")
    vals = np.clip(vals - 0.5 * float(vals.max()), 0.0, None)  # the upper half only
    if not np.any(vals > 0):
        return point
    return point + float(np.sum(offs * vals) / np.sum(vals)) * normal


def snap_click(
    vmap: VesselnessMap, point_px: ArrayLike, *, max_distance_px: float = 8.0
) -> tuple[FloatArray, float]:
    """Move a click across the vessel onto its centre (module docstring).

    Parameters
    ----------
    vmap : the image's vesselness.
    point_px : (2,) click (col, row).
    max_distance_px : farthest the click may be from a vessel's lumen.

    Returns
    -------
    snapped_px : (2,) (col, row) on the ridge centre.
    distance_px : distance from the click to the snapped point.

    Raises
    ------
    TraceError if no vessel lumen lies within ``max_distance_px`` of the click.
    """
    p = np.asarray(point_px, dtype=float).reshape(-1)
    if p.shape != (2,) or not np.all(np.isfinite(p)):
        raise TraceError(f"click must be a finite (col, row) pair, got {point_px!r}")
    h, w = vmap.shape
    col, row = float(p[0]), float(p[1])
    where = f"click at ({col:.1f}, {row:.1f})"
    if not (-0.5 <= col <= w - 0.5 and -0.5 <= row <= h - 0.5):
        raise TraceError(f"{where} is outside the {w}x{h} image")
    r_max = RADIUS_PER_SIGMA * float(max(vmap.sigmas_px))
    search = max(float(max_distance_px), 0.0) + r_max + 3.0
    r0, r1 = max(int(np.floor(row - search)), 0), min(int(np.ceil(row + search)) + 1, h)
    c0, c1 = max(int(np.floor(col - search)), 0), min(int(np.ceil(col + search)) + 1, w)
    ridge = vmap.response if vmap.ridge is None else vmap.ridge
    resp = ridge[r0:r1, c0:c1]
    strength = resp if vmap.strength is None else vmap.strength[r0:r1, c0:c1]
    theta = (np.zeros_like(resp) if vmap.direction_rad is None
             else vmap.direction_rad[r0:r1, c0:c1])
    rr, cc = np.mgrid[r0:r1, c0:c1]
    tx, ty = np.cos(theta), np.sin(theta)  # tangent (col, row)
    nx, ny = -ty, tx  # normal
    # Ridge centres: responding pixels that are a maximum of the strength across.
    cand = resp >= RIDGE_LEVEL
    idx = np.nonzero(cand)
    if len(idx[0]):
        pos_r, pos_c = idx[0] + r0, idx[1] + c0
        full = ridge if vmap.strength is None else vmap.strength
        ahead = ndi.map_coordinates(full, [pos_r + ny[idx], pos_c + nx[idx]], order=1,
                                    mode="nearest")
        behind = ndi.map_coordinates(full, [pos_r - ny[idx], pos_c - nx[idx]], order=1,
                                     mode="nearest")
        here = strength[idx]
        peak = (here >= ahead) & (here >= behind)
        cand[idx[0][~peak], idx[1][~peak]] = False
        # Subpixel centre: a parabola through the strength at -s, 0, +s across, s
        # a third of the radius (the peak of a wide vessel is flat over 1 px).
        step = np.maximum(1.0, RADIUS_PER_SIGMA * vmap.scale_px[pos_r, pos_c] / 3.0)
        ahead_h = ndi.map_coordinates(full, [pos_r + step * ny[idx], pos_c + step * nx[idx]],
                                      order=1, mode="nearest")
        behind_h = ndi.map_coordinates(full, [pos_r - step * ny[idx], pos_c - step * nx[idx]],
                                       order=1, mode="nearest")
        offset = np.zeros_like(resp, dtype=float)
        offset[idx] = step * _parabola_offset(behind_h, here, ahead_h)  # along +n, in px
    else:
        offset = np.zeros_like(resp, dtype=float)
    if not np.any(cand):
        raise TraceError(f"{where} is more than {search:.0f} px from any vessel")
    # Candidate centre (subpixel) and the click's position relative to it.
    qx = cc + offset * nx
    qy = rr + offset * ny
    dx, dy = col - qx, row - qy
    along = np.abs(dx * tx + dy * ty)
    across_signed = dx * nx + dy * ny
    radius = RADIUS_PER_SIGMA * vmap.scale_px[r0:r1, c0:c1].astype(float)
    gap = np.maximum(np.abs(across_signed) - radius, 0.0)  # click to the lumen
    gap_all = np.where(cand, gap, np.inf)
    d_near = float(gap_all.min())
    if d_near > max_distance_px:
        raise TraceError(
            f"{where} is {d_near:.1f} px from any vessel (max {max_distance_px:g} px)"
        )
    ok = cand & (gap <= max_distance_px)
    level = ok & (along <= 1.0)
    if not np.any(level):  # beyond a vessel's end: allow up to one radius along it
        level = ok & (along <= np.maximum(radius, 1.0))
    if not np.any(level):
        level = ok & (along <= np.maximum(radius, 1.0) + max_distance_px)
        if not np.any(level):
            raise TraceError(f"{where} is beside no vessel (the nearest one ends farther "
                             f"than {max_distance_px:g} px along it)")
    inside = level & (gap <= 0.0)
    if np.any(inside):  # the click is in a lumen: the strongest such vessel
        score = np.where(inside, strength - 1e-3 * along, -np.inf)
    else:  # the nearest lumen, then the nearest centre
        score = np.where(level, -(gap + 1e-3 * np.abs(across_signed) + 0.1 * along), -np.inf)
    k = int(np.argmax(score))
    # Move the click across by the candidate's offset (no move along its tangent),
    # except at a vessel's end where the candidate itself is taken.
    kr, kc = np.unravel_index(k, score.shape)
    normal = np.array([nx[kr, kc], ny[kr, kc]])
    if along[kr, kc] <= 1.0:
        snapped = p - across_signed[kr, kc] * normal
    else:
        snapped = np.array([qx[kr, kc], qy[kr, kc]])
    snapped = _centroid_across(ridge, snapped, normal, float(radius[kr, kc]))
    snapped = np.clip(snapped, [0.0, 0.0], [w - 1.0, h - 1.0])
    return snapped, float(np.hypot(*(snapped - p)))
