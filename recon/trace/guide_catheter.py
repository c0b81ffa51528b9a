"""The guiding catheter in one view: a tube of steady width that enters the field at its edge.

A guiding catheter (4-8 F: 1.3-2.7 mm outer diameter, 1 F = 1/3 mm) runs from
outside the collimated field to the coronary ostium it is engaged in. In the
image it is a dark tube that crosses the field's edge and keeps its width for
tens of millimetres, where a coronary artery tapers and branches. A trace
between two clicks must not run along it (issue 13: a real clinical trace did).

:func:`find_catheters` follows every such tube inwards from the field's edge
with a ridge tracker on the contrast-invariant ridge measure
(:attr:`VesselnessMap.ridge`). It starts at the strongest ridge pixel of each
piece of tube-wide ridge 1-3 :data:`EDGE_PX` inside the field (clear of the
collimator's rim); each step moves one lumen radius along the current heading
and is re-centred on the ridge's maximum across it, at most :data:`RECENTRE`
radii sideways; the heading follows the local vessel direction, turning no
tighter than a :data:`MIN_BEND_MM` radius of curvature. Where the local
direction differs from the heading by more than :data:`KINK_DEG` (a vessel
crossing the tube, or a kink) or the ridge is lost, the track goes straight on,
for at most :data:`MAX_MISSES` steps. It ends there, where its width leaves the
width it entered with (the tip, where the catheter meets the artery), on
coming near a click (the clicked vessel is never part of it), or on leaving the
field again. A track is a catheter when it ends inside the field, is at least
:data:`MIN_LENGTH_MM` long with its lumen radius in :data:`RADIUS_RANGE_MM`,
and is a tube, not a step: darker on its centre line than on both sides at
:data:`MIN_DIP_FRACTION` of its points, with sides that differ by at most
:data:`MAX_ASYMMETRY` of that dip (the dark rim that edge enhancement draws
along a rib is not a tube), and at least :data:`MIN_CONTRAST` of the clicked
vessel's dip (a catheter holds undiluted contrast; a rib's cortex is faint).

The route (:mod:`recon.trace.trace_path`) pays more for moving along a catheter,
not for crossing it, and a trace that still runs along one is refused with the
place named (:func:`catheter_runs`).

Pixels are (col, row), 0-based.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage as ndi
from scipy.spatial import cKDTree

from recon.trace.vesselness import RADIUS_PER_SIGMA, VesselnessMap
from recon.types import arclength

__all__ = ["Catheter2D", "find_catheters", "catheter_runs", "MIN_LENGTH_MM", "RADIUS_RANGE_MM"]

FloatArray = NDArray[np.float64]

#: Lumen radius (mm at the vessel) of a catheter as the vesselness reads it: a 4-8 F
#: tube (outer radius 0.67-1.33 mm) whose contrast-filled lumen is narrower.
RADIUS_RANGE_MM = (0.45, 1.6)
#: Without a pixel size, the largest radius (px) a catheter track may have.
RADIUS_MAX_PX_NO_SIZE = 8.0
#: Shortest catheter track (mm at the vessel; 60 px without a pixel size).
MIN_LENGTH_MM = 20.0
MIN_LENGTH_PX_NO_SIZE = 60.0
#: Ridge measure a track starts from and keeps (the band's level of the route).
RIDGE_START = 0.35
RIDGE_KEEP = 0.15
#: Steps in a row below RIDGE_KEEP (gone straight on) before the track ends.
MAX_MISSES = 3
#: Largest sideways re-centring per step, in radii (a tube's centre does not jump; a
#: track hopping onto a neighbour would).
RECENTRE = 0.5
#: Smoothing (Gaussian sigma, in steps) of a track's centre line.
SMOOTH_STEPS = 1.5
#: A local direction this far from the track's heading is a kink or a crossing vessel.
KINK_DEG = 40.0
#: Largest heading change per step.
MAX_TURN_DEG = 25.0
#: Tightest bend of a catheter (radius of curvature, mm at the vessel; px without a
#: pixel size): the track does not follow a kink, where a vessel branches or a track
#: hops from one structure to another.
MIN_BEND_MM = 4.0
MIN_BEND_PX_NO_SIZE = 12.0
#: A tube's two sides differ by at most this fraction of its dip (median along it).
MAX_ASYMMETRY = 0.6
#: Width steadiness: a track ends where the median radius of its last :data:`WINDOW`
#: steps leaves this factor of its median over the first :data:`ENTRY_STEPS` steps
#: (the scale map's radius moves in steps of sqrt 2, so single reads are coarse).
WIDTH_FACTOR = 1.5
ENTRY_STEPS = 8
WINDOW = 5
#: A tube is darker on its centre line than on both sides at this fraction of its points.
MIN_DIP_FRACTION = 0.8
#: A catheter's median dip is at least this fraction of the clicked vessel's (its lumen
#: holds undiluted contrast; the cortex of a rib is far fainter).
MIN_CONTRAST = 0.5
#: Start pixels lie 1-3 times this distance (px) inside the field's edge.
EDGE_PX = 6
#: At most this many start places are followed (the largest pieces of ridge first).
MAX_STARTS = 48
#: A track ends this many of its radii (plus the click's lumen) before a click.
CLICK_CLEARANCE = 2.0


@dataclass(frozen=True)
class Catheter2D:
    """A catheter-like tube in one image, from the field's edge inwards.

    points_px : (N, 2) its centre line (col, row), from the field's edge to where
        the track ended (the tip, or short of a click).
    radius_px : (N,) its lumen radius along it (from the vesselness scale).
    """

    points_px: FloatArray
    radius_px: FloatArray

    @property
    def length_px(self) -> float:
        return float(arclength(self.points_px)[-1])

    @property
    def tip_px(self) -> FloatArray:
        return self.points_px[-1]


def _sample(arr: NDArray, points_px: FloatArray, order: int = 1) -> FloatArray:
    p = np.asarray(points_px, dtype=float).reshape(-1, 2)
    return ndi.map_coordinates(arr, [p[:, 1], p[:, 0]], order=order, mode="nearest")


def _starts(vmap: VesselnessMap, ridge: NDArray, radius_ok: NDArray[np.bool_]) -> FloatArray:
    """Start pixels (S, 2): the strongest ridge pixel of each tube piece at the field's edge."""
    valid = vmap.valid
    # square erosions (one separable pass each): clear of the collimator's rim, then the
    # band 1-3 EDGE_PX inside the field
    field = valid.view(np.uint8)
    inner = ndi.minimum_filter(field, size=2 * EDGE_PX + 1).astype(bool)
    edge = inner & ~ndi.minimum_filter(field, size=6 * EDGE_PX + 1).astype(bool)
    cand = edge & (ridge >= RIDGE_START) & radius_ok
    labels, n = ndi.label(cand, structure=np.ones((3, 3)))
    if n == 0:
        return np.zeros((0, 2))
    flat = np.flatnonzero(cand)  # only the candidates, not the whole image
    lab, val = labels.ravel()[flat], ridge.ravel()[flat]
    by = np.lexsort((-val, lab))  # by piece, strongest first
    first = by[np.concatenate([[True], np.diff(lab[by]) > 0])]
    size = np.bincount(lab, minlength=n + 1)[lab[first]]
    best = flat[first[np.argsort(-size, kind="stable")[:MAX_STARTS]]]
    rows, cols = np.unravel_index(best, cand.shape)
    return np.column_stack([cols, rows]).astype(float)


def _mid(values: list[float]) -> float:
    """Median of a short list (the upper one of an even count)."""
    return sorted(values)[len(values) // 2]


def _heading(vmap: VesselnessMap, p: FloatArray) -> FloatArray:
    phi = float(_sample(vmap.direction_rad, p, order=0)[0])
    return np.array([np.cos(phi), np.sin(phi)])


def _turned(d_old: FloatArray, d_new: FloatArray, max_turn_rad: float
            ) -> FloatArray | None:
    """``d_new`` (oriented along ``d_old``), turned at most ``max_turn_rad`` from ``d_old``;
    None where the two differ by more than :data:`KINK_DEG` (a kink, or a vessel
    crossing the tube: the track goes straight on)."""
    if d_new @ d_old < 0:
        d_new = -d_new
    a_old, a_new = np.arctan2(d_old[1], d_old[0]), np.arctan2(d_new[1], d_new[0])
    delta = (a_new - a_old + np.pi) % (2 * np.pi) - np.pi
    if abs(delta) > np.deg2rad(KINK_DEG):
        return None
    a = a_old + float(np.clip(delta, -max_turn_rad, max_turn_rad))
    return np.array([np.cos(a), np.sin(a)])


def _track(vmap: VesselnessMap, ridge: NDArray, start: FloatArray, clicks_px: FloatArray,
           click_r_px: FloatArray, bend_px: float) -> tuple[FloatArray, FloatArray, bool]:
    """Follow the tube from ``start`` (2,) inwards, bending no tighter than ``bend_px``
    (radius of curvature); its points (N, 2), radii (N,), and whether it ended by
    leaving the field."""
    field = vmap.valid
    d = _heading(vmap, start)
    r0 = float(vmap.radius_px_at(start)[0])
    probe = start + d * 3 * EDGE_PX
    back = start - d * 3 * EDGE_PX
    fwd_in = bool(_sample(field, probe, order=0)[0])
    back_in = bool(_sample(field, back, order=0)[0])
    if back_in and not fwd_in:
        d = -d
    n0 = np.array([-d[1], d[0]])
    offsets = np.arange(-np.ceil(r0), np.ceil(r0) + 0.01, 0.5)
    values = _sample(ridge, start[None, :] + offsets[:, None] * n0[None, :])
    top = values >= values.max() - 1e-3  # the start in the middle of the ridge's top
    p = start + float(np.mean(offsets[top])) * n0
    points, radii = [p.copy()], [r0]
    misses, off_width, left_field = 0, 0, False
    max_steps = int(4 * sum(vmap.shape) / max(1.0, r0))
    for _ in range(max_steps):
        r = _mid(radii[-3:])
        step = max(1.5, r)
        n = np.array([-d[1], d[0]])
        half = max(1.0, RECENTRE * r)
        offsets = np.arange(-half, half + 0.01, 0.5)
        pred = p + step * d
        across = pred[None, :] + offsets[:, None] * n[None, :]
        values = _sample(ridge, across)
        # the strongest; on the ridge's flat top (it saturates across a wide lumen)
        # the one nearest straight on
        centre = across[int(np.argmax(values - 1e-3 * np.abs(offsets)))]
        turned = _turned(d, _heading(vmap, centre),
                         min(step / bend_px, np.deg2rad(MAX_TURN_DEG)))
        if values.max() < RIDGE_KEEP or turned is None:
            misses += 1  # lost, or kinked: straight on for a few steps
            if misses > MAX_MISSES:
                break
            p = pred
        else:
            misses = 0
            p, d = centre, turned
        if not bool(_sample(field, p, order=0)[0]):
            left_field = True
            break
        if len(clicks_px):
            gap = np.linalg.norm(clicks_px - p, axis=1) - click_r_px
            if np.any(gap < CLICK_CLEARANCE * r):
                break
        points.append(p.copy())
        radii.append(float(vmap.radius_px_at(p)[0]))
        if len(radii) >= ENTRY_STEPS + WINDOW:
            entry, here = _mid(radii[:ENTRY_STEPS]), _mid(radii[-WINDOW:])
            if not entry / WIDTH_FACTOR <= here <= entry * WIDTH_FACTOR:
                off_width += 1
                if off_width >= WINDOW // 2:  # the tip: drop the window past it
                    del points[-WINDOW:], radii[-WINDOW:]
                    break
            else:
                off_width = 0
    keep = max(len(points) - misses, 1)
    pts = np.asarray(points[:keep])
    if len(pts) >= 3:  # the re-centring's jitter (half a pixel's grid, noise) smoothed
        pts = ndi.gaussian_filter1d(pts, SMOOTH_STEPS, axis=0, mode="nearest")
    return pts, np.asarray(radii[:keep]), left_field


def _dips(image: NDArray, points_px: FloatArray, tangents: FloatArray,
          radius_px: FloatArray) -> tuple[FloatArray, FloatArray]:
    """How much darker (N,) the image is on the centre line (mean over the inner half
    radius) than the darker of its two sides (means over 2-3 radii out), at points
    (N, 2) with unit tangents (N, 2): positive for a tube, not for a step such as the
    edge of a rib, the diaphragm or the table; and how much the two sides differ (N,):
    small for a tube, large for the dark rim an edge-enhancing display draws along a
    step."""
    n = np.column_stack([-tangents[:, 1], tangents[:, 0]])
    u = np.linspace(0.0, 1.0, 5)
    means = []
    for lo, hi in ((-0.5, 0.5), (2.0, 3.0), (-3.0, -2.0)):
        off = (lo + (hi - lo) * u)[None, :] * radius_px[:, None]  # (N, 5)
        pts = points_px[:, None, :] + off[..., None] * n[:, None, :]
        means.append(_sample(image, pts.reshape(-1, 2)).reshape(len(points_px), -1).mean(1))
    centre, left, right = means
    return np.minimum(left, right) - centre, np.abs(left - right)


def _is_tube(dip: FloatArray, asym: FloatArray, ref_dip: float, min_fraction: float) -> bool:
    """Whether a stretch's dips and side differences (:func:`_dips`) are a tube's: dark
    on the centre at ``min_fraction`` of its points, a median dip of at least
    :data:`MIN_CONTRAST` of ``ref_dip`` (and above 0), sides within
    :data:`MAX_ASYMMETRY` of it."""
    depth = float(np.median(dip))
    return bool(np.mean(dip > 0) >= min_fraction and depth > 0
                and depth >= MIN_CONTRAST * ref_dip
                and np.median(asym) <= MAX_ASYMMETRY * depth)


def _tangents(points_px: FloatArray) -> FloatArray:
    t = np.gradient(points_px, axis=0)
    return t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-9)


def find_catheters(vmap: VesselnessMap, image: ArrayLike,
                   clicks_px: ArrayLike | None = None) -> tuple[Catheter2D, ...]:
    """Catheter-like tubes (module docstring) of an image and its vesselness ``vmap``.

    image : (H, W) the stored values, MONOCHROME2 (a contrast-filled tube is dark);
        a track is kept only where it is darker than both its sides
        (:data:`MIN_DIP_FRACTION` of its points).
    clicks_px : (K, 2) clicks (col, row) on the vessel being traced, or None: a
        track ends before reaching one, so the clicked vessel is never taken for
        a catheter.

    Returns the tubes found, longest first (usually none or one).
    """
    if vmap.direction_rad is None:
        return ()
    ridge = vmap.ridge if vmap.ridge is not None else vmap.response
    img = np.asarray(image, dtype=np.float32)
    r_map = vmap.scale_px * np.float32(RADIUS_PER_SIGMA)
    if vmap.pixel_mm:
        lo, hi = (v / vmap.pixel_mm for v in RADIUS_RANGE_MM)
        min_len = MIN_LENGTH_MM / vmap.pixel_mm
        bend_px = MIN_BEND_MM / vmap.pixel_mm
    else:
        lo, hi, min_len = 0.0, RADIUS_MAX_PX_NO_SIZE, MIN_LENGTH_PX_NO_SIZE
        bend_px = MIN_BEND_PX_NO_SIZE
    radius_ok = (r_map >= lo) & (r_map <= hi)
    clicks = (np.zeros((0, 2)) if clicks_px is None
              else np.asarray(clicks_px, dtype=float).reshape(-1, 2))
    click_r = vmap.radius_px_at(clicks) if len(clicks) else np.zeros(0)
    ref_dip = 0.0  # the clicked vessel's contrast, the catheter's reference
    if len(clicks):
        phi = _sample(vmap.direction_rad, clicks, order=0)
        ref_dip = max(0.0, float(np.median(
            _dips(img, clicks, np.column_stack([np.cos(phi), np.sin(phi)]), click_r)[0])))
    found: list[Catheter2D] = []  # tubes kept so far
    for start in _starts(vmap, ridge, radius_ok):
        if any(np.min(np.linalg.norm(c.points_px - start, axis=1)) < 2 * np.median(c.radius_px)
               for c in found):
            continue  # already on a track
        if len(clicks) and np.any(np.linalg.norm(clicks - start, axis=1) - click_r
                                  < CLICK_CLEARANCE * vmap.radius_px_at(start)[0] + click_r):
            continue  # the clicked vessel itself reaches the field's edge here
        # a first look at the start (5 points over 4 radii): most steps and rims fail here
        r_s = float(vmap.radius_px_at(start)[0])
        d_s = _heading(vmap, start)
        near = start + np.outer(np.linspace(-2.0, 2.0, 5) * r_s, d_s)
        if not _is_tube(*_dips(img, near, np.tile(d_s, (5, 1)), np.full(5, r_s)), ref_dip,
                        0.0):
            continue
        pts, rad, left_field = _track(vmap, ridge, start, clicks, click_r, bend_px)
        if len(pts) < 3 or left_field:
            continue  # a catheter ends inside the field, at its tip
        if not _is_tube(*_dips(img, pts, _tangents(pts), rad), ref_dip, MIN_DIP_FRACTION):
            continue
        if any(_shared(pts, c) > 0.5 for c in found):
            continue  # the same tube, entered elsewhere
        cath = Catheter2D(points_px=pts, radius_px=rad)
        r_med = float(np.median(rad))
        if cath.length_px >= min_len and lo <= r_med <= hi:
            found.append(cath)
    return tuple(sorted(found, key=lambda c: -c.length_px))


def _shared(points_px: FloatArray, other: Catheter2D) -> float:
    """Fraction of ``points_px`` (N, 2) within the lumen of the tube ``other``."""
    d, _ = cKDTree(other.points_px).query(points_px)
    return float(np.mean(d <= np.median(other.radius_px)))


def catheter_runs(points_px: ArrayLike, catheters: tuple[Catheter2D, ...],
                  min_run_px: float) -> list[tuple[int, int]]:
    """Stretches of a path ``points_px`` (N, 2) that run along a catheter: index ranges
    [i, j) of consecutive points inside a catheter's lumen (its radius + 1 px from its
    centre line) whose direction is within 30 degrees of the catheter's, at least
    ``min_run_px`` long."""
    pts = np.asarray(points_px, dtype=float)
    if len(pts) < 2 or not catheters:
        return []
    tangent = _tangents(pts)
    along = np.zeros(len(pts), dtype=bool)
    for cath in catheters:
        dist, near = cKDTree(cath.points_px).query(pts)
        inside = dist <= cath.radius_px[near] + 1.0
        parallel = (np.abs(np.sum(tangent * _tangents(cath.points_px)[near], axis=1))
                    >= np.cos(np.deg2rad(30.0)))
        along |= inside & parallel
    s = arclength(pts)
    edges = np.diff(np.concatenate([[0], along.astype(int), [0]]))
    runs = zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True)
    return [(int(i), int(j)) for i, j in runs if s[j - 1] - s[i] >= min_run_px]
