"""From the 3D path to each view's 2D trace: the path's image fixes the topology.

The 3D path decides which vessel, and which way round a loop or through a crossing;
the sub-pixel centre and radius stay with the 2D fits (:func:`recon.trace.trace_segment`).
So each view is traced as today, but on a vesselness map cut to a corridor around the
path's image: outside it the ridge measures are zero, so neither the snapping of the
clicks nor the 2D route can leave for a neighbour, the other limb of a loop or the
guiding catheter.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage as ndi

from recon.geometry import ViewGeometry, ray_distance_mm
from recon.trace.snapping import snap_click
from recon.trace.trace_error import TraceError
from recon.trace.vesselness import VesselnessMap
from recon.trace3d.path3d import Path3D

__all__ = ["corridor_map", "corridor_maps", "snap_ends", "clicks_on_path", "CORRIDOR_MIN_PX",
           "CORRIDOR_PER_RADIUS"]

FloatArray = NDArray[np.float64]

#: Half-width of the corridor (px): at least this, or this many vessel radii.
CORRIDOR_MIN_PX = 3.0
CORRIDOR_PER_RADIUS = 1.0
#: Clicks closer than this (px) are refused by the 2D tracing (recon.trace.centerline).
MIN_CLICK_GAP_PX = 2.0


def corridor_map(vmap: VesselnessMap, path_px: FloatArray) -> VesselnessMap:
    """``vmap`` with its ridge measures zeroed farther than the corridor's half-width
    from the polyline ``path_px`` (M, 2) (col, row): the path's image in this view."""
    h, w = vmap.shape
    r_px = np.median(vmap.radius_px_at(np.clip(path_px, 0, [w - 1, h - 1])))
    half = max(CORRIDOR_MIN_PX, CORRIDOR_PER_RADIUS * float(r_px))
    pad = int(np.ceil(half)) + 2
    c0, r0 = np.maximum(np.floor(path_px.min(axis=0)).astype(int) - pad, 0)
    c1, r1 = np.minimum(np.ceil(path_px.max(axis=0)).astype(int) + pad + 1, [w, h])
    line = np.ones((r1 - r0, c1 - c0), dtype=bool)
    dense = _densify(path_px, 0.5)
    q = np.rint(dense - [c0, r0]).astype(int)
    inside = (q[:, 0] >= 0) & (q[:, 0] < c1 - c0) & (q[:, 1] >= 0) & (q[:, 1] < r1 - r0)
    line[q[inside, 1], q[inside, 0]] = False
    mask = np.zeros((h, w), dtype=np.float32)
    mask[r0:r1, c0:c1] = ndi.distance_transform_edt(line) <= half

    def cut(a: NDArray | None) -> NDArray | None:
        return None if a is None else (a * mask).astype(a.dtype)

    return replace(vmap, response=cut(vmap.response), ridge=cut(vmap.ridge),
                   strength=cut(vmap.strength), junction=cut(vmap.junction))


def _densify(p: FloatArray, step_px: float) -> FloatArray:
    """Points along the polyline p (M, 2) at most ``step_px`` apart."""
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    at = np.linspace(0.0, s[-1], max(int(np.ceil(s[-1] / step_px)) + 1, 2))
    return np.column_stack([np.interp(at, s, p[:, 0]), np.interp(at, s, p[:, 1])])


def snap_ends(vmaps: tuple[VesselnessMap, VesselnessMap], clicks_a_px: FloatArray,
              clicks_b_px: FloatArray, view_a: ViewGeometry,
              view_b: ViewGeometry) -> tuple[FloatArray, FloatArray]:
    """The end clicks (2, 2) of each view, each as clicked or snapped across its vessel,
    whichever pair of the four meets best in 3D (the rays' distance): a click snapped
    onto a stronger neighbour in one view does not meet its partner in the other.

    ``view_b`` is B's header pose: the choice compares the pairs under one pose, so a
    pose error common to all four does not change it.
    """
    out = []
    for k in (0, -1):
        cand = []
        for vmap, clicks, view in ((vmaps[0], clicks_a_px, "A"), (vmaps[1], clicks_b_px, "B")):
            p = np.asarray(clicks, dtype=float)[k]
            try:
                snapped, _ = snap_click(vmap, p)
            except TraceError as err:
                role = "proximal" if k == 0 else "distal"
                raise TraceError(f"view {view}: the {role} click: {err}", view=view,
                                 near_px=p) from None
            cand.append(np.array([snapped, p]))
        pairs = [(i, j) for i in range(2) for j in range(2)]
        a_px = np.array([cand[0][i] for i, _ in pairs])
        b_px = np.array([cand[1][j] for _, j in pairs])
        gap = ray_distance_mm(a_px, b_px, view_a, view_b)
        # the snapped pair unless an unsnapped click meets clearly better
        best = int(np.argmin(gap + np.array([0.0, 0.3, 0.3, 0.6])))
        out.append((a_px[best], b_px[best]))
    return np.array([out[0][0], out[1][0]]), np.array([out[0][1], out[1][1]])


def clicks_on_path(clicks_px: FloatArray, path_px: FloatArray) -> FloatArray:
    """The clicks (K, 2) the 2D tracing starts from inside the corridor: the end clicks as
    clicked (the path's image is extended to them), each waypoint moved to the nearest
    point of the path's image (M, 2), in order."""
    clicked = np.asarray(clicks_px, dtype=float)
    c = clicked.copy()
    if len(c) > 2:
        d = np.linalg.norm(c[1:-1, None, :] - path_px[None, :, :], axis=2)
        at = np.maximum.accumulate(np.argmin(d, axis=1))
        c[1:-1] = path_px[at]
        # a waypoint that would land on its neighbour (the path passed them at one place)
        # stays as clicked
        close = np.linalg.norm(np.diff(c, axis=0), axis=1) < MIN_CLICK_GAP_PX
        for i in np.nonzero(close)[0]:
            for j in (i, i + 1):
                if 0 < j < len(c) - 1:
                    c[j] = clicked[j]
    return c


def extended(path_px: FloatArray, clicks_px: FloatArray) -> FloatArray:
    """The path's image (M, 2) extended to the end clicks (the path's ends lie within a few
    px of them)."""
    c = np.asarray(clicks_px, dtype=float)
    return np.vstack([c[:1], path_px, c[-1:]])


def corridor_maps(vmaps: tuple[VesselnessMap, VesselnessMap], path: Path3D,
                  views: tuple[ViewGeometry, ViewGeometry],
                  clicks_px: tuple[FloatArray, FloatArray]) -> tuple[VesselnessMap, ...]:
    """Both views' corridor maps around the path's images, extended to the end clicks."""
    return tuple(corridor_map(v, extended(path.projected(g), c))
                 for v, g, c in zip(vmaps, views, clicks_px, strict=True))
