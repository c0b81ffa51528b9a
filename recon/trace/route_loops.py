"""Loops of the vessel that a route cut across, found in the route's band.

A loop that overlaps itself in projection shows as a ring of ridge touching the
route twice (:func:`loop_apices`); a tight loop's ring, whose hole shows above the
band's level, as a hole of the band (:func:`ring_circuits`).
:mod:`recon.trace.trace_path` follows the route round the loops found.

Pixels are (col, row), 0-based; masks and maps are (H, W) grids of the route's crop.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage as ndi
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree
from skimage.measure import find_contours
from skimage.morphology import skeletonize

__all__ = ["loop_apices", "ring_circuits", "route_distance"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def loop_apices(band: NDArray[np.bool_], path_px: FloatArray, radius_px: float,
                lumen_px: FloatArray | None = None, *,
                route_dist_px: FloatArray | None = None) -> list[tuple[int, FloatArray]]:
    """Loops of the vessel that a route (M, 2) cut across, in a band's pixels (col, row).

    A loop that overlaps itself in projection is a ring of ridge touching the route
    at its crossing: the band's skeleton (Zhang & Suen's thinning, scikit-image)
    outside a tube of 2.5 r + 3 px around the route (past the crossing's blob) has
    a piece that meets the tube in two places less than max(6 r, 30) px of route
    apart, joined through the piece by a skeleton path longer than twice that
    stretch of route plus 2 r that reaches farther than 2.5 r from the route, away
    from the route's ends, and along which the lumen (``lumen_px``: radius map
    (H, W) of the band's pixels, if given) is at least 0.7 r: a vessel keeps its
    calibre round a loop. (A branch meets the tube once; a vessel crossing the
    route leaves two pieces that meet it once each; two branches that meet make
    a ring of thinner vessels.)

    ``route_dist_px``: :func:`route_distance` of the route, if already computed.
    Returns (route index of the crossing, the loop's apex (2,): the middle of that
    skeleton path), in route order.
    """
    dist = route_distance(band.shape, path_px) if route_dist_px is None else route_dist_px
    tube_px = 2.5 * radius_px + 3.0
    pieces = np.zeros(band.shape, dtype=bool)  # the skeleton (a local thinning) on the band's box
    if np.any(band):
        box = _box(band, 1)
        pieces[box] = skeletonize(band[box])
    pieces &= dist > tube_px
    labels, n = ndi.label(pieces, structure=np.ones((3, 3)))
    if n == 0:
        return []
    s_route = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path_px, axis=0),
                                                              axis=1))])
    tree = cKDTree(path_px)
    max_span = max(6.0 * radius_px, 30.0)
    found: list[tuple[int, FloatArray]] = []
    sizes = np.bincount(labels.ravel())
    for k in np.nonzero(sizes >= max(3.0 * radius_px, 12.0))[0]:
        if k == 0:
            continue
        rows, cols = np.nonzero(labels == k)
        touch = dist[rows, cols] <= tube_px + 2.0
        if np.count_nonzero(touch) < 2:
            continue
        path = _contact_path(rows, cols, touch)
        if path is None:
            continue
        pr, pc = rows[path], cols[path]
        if dist[pr, pc].max() < 2.5 * radius_px:
            continue
        if lumen_px is not None and float(np.median(lumen_px[pr, pc])) < 0.7 * radius_px:
            continue
        _, at = tree.query(np.column_stack([cols[touch], rows[touch]]).astype(float))
        s_at = s_route[at]
        if s_at.min() < tube_px + 2.0 or s_at.max() > s_route[-1] - tube_px - 2.0:
            continue  # the vessel going on past an end click, round the tube's end
        span = float(s_at.max() - s_at.min())
        length = float(np.sum(np.hypot(np.diff(pr), np.diff(pc))))
        if span > max_span or length < 2.0 * span + 2.0 * radius_px:
            continue
        mid = path[len(path) // 2]
        found.append((int(np.median(at)), np.array([cols[mid], rows[mid]], dtype=float)))
    return sorted(found, key=lambda item: item[0])


def route_distance(shape: tuple[int, int], path_px: FloatArray) -> FloatArray:
    """Euclidean distance (px) of each pixel of a (H, W) grid to a route (M, 2) (col, row)."""
    rc = np.rint(path_px[:, ::-1]).astype(int)
    rc = rc[np.all((rc >= 0) & (rc < shape), axis=1)]
    off_route = np.ones(shape, dtype=bool)
    off_route[rc[:, 0], rc[:, 1]] = False
    return ndi.distance_transform_edt(off_route)


def ring_circuits(band: NDArray[np.bool_], path_px: FloatArray,
                  radius_px: float) -> list[tuple[int, FloatArray]]:
    """Tight loops that a route (M, 2) cut across, found as holes of a band (col, row).

    The ring of a loop about two lumens wide lies mostly inside the tube that
    :func:`loop_apices` leaves out, but at a response level above the band's it
    encloses a hole (after a binary closing of one pixel). A hole counts as a loop's
    when a disc of radius 0.6 r fits in it, it is at most (8 r)^2 px in area, and
    the route comes within 1.5 r + 2 px of the ring's centre line (the iso-line at r
    from the hole, scikit-image's marching squares) along at most 4 r + 4 px of
    route (the loop's crossing; a route that already runs along the ring, or a
    hole between the vessel, a branch and a crossing vessel, meets it along a
    side), farther than 2.5 r + 5 px from the route's ends, and half of that
    centre line lies in the band.

    Returns (route index of the crossing, the ring's centre line (P, 2) as a closed
    circuit from and back to its point nearest the crossing, heading the way the
    route heads there), in route order.
    """
    if not np.any(band):
        return []
    # On the band's box grown by 3 px, the same as on the whole grid: the closing reaches
    # 2 px out, and the box's empty rim joins every outside pixel to the grid's edge.
    box, sub = _box(band, 3), np.zeros_like(band)
    sub[box] = ndi.binary_closing(band[box])  # a ring broken by one pixel still encloses its hole
    band, holes = sub, np.zeros_like(band)
    holes[box] = ndi.binary_fill_holes(band[box]) & ~band[box]
    labels, n = ndi.label(holes)
    if n == 0:
        return []
    areas = np.bincount(labels.ravel())
    rr, cc = np.nonzero(holes)  # their box + 1 px holds their nearest non-hole pixels
    r0, c0, inscribed = rr.min() - 1, cc.min() - 1, np.zeros(n + 1)
    d_in = ndi.distance_transform_edt(holes[r0 : rr.max() + 2, c0 : cc.max() + 2])
    np.maximum.at(inscribed, labels[rr, cc], d_in[rr - r0, cc - c0])
    s_route = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path_px, axis=0),
                                                              axis=1))])
    step = float(np.median(np.diff(s_route))) if len(s_route) > 1 else 1.0
    tangent = np.gradient(path_px, axis=0)
    found: list[tuple[int, FloatArray]] = []
    for k in range(1, n + 1):
        if inscribed[k] < 0.6 * radius_px or areas[k] > 64.0 * radius_px**2:
            continue  # a sliver between a vessel and a branch, or not one ring
        d_hole = ndi.distance_transform_edt(labels != k)
        lines = [c for c in find_contours(d_hole, radius_px)
                 if len(c) > 8 and np.allclose(c[0], c[-1])]
        if not lines:
            continue
        ring = max(lines, key=len)[:-1, ::-1]  # (P, 2) (col, row), closed
        ring_rc = np.rint(ring[:, ::-1]).astype(int)
        if np.mean(band[ring_rc[:, 0], ring_rc[:, 1]]) < 0.5:
            continue  # the iso-line leaves the band: no ring of the vessel's calibre
        d_route, j_ring = cKDTree(ring).query(path_px)
        near = np.flatnonzero(d_route <= 1.5 * radius_px + 2.0)
        if not len(near) or len(near) * step > 4.0 * radius_px + 4.0:
            continue
        i = int(near[np.argmin(d_route[near])])
        end_px = 2.5 * radius_px + 5.0  # as loop_apices: past the crossing's blob
        if s_route[i] < end_px or s_route[i] > s_route[-1] - end_px:
            continue
        j = int(j_ring[i])
        circuit = np.roll(ring, -j, axis=0)
        if np.dot(circuit[1] - circuit[0], tangent[i]) < 0:
            circuit = np.roll(circuit[::-1], 1, axis=0)
        found.append((i, np.vstack([circuit, circuit[:1]])))
    return sorted(found, key=lambda item: item[0])


def _box(mask: NDArray[np.bool_], pad_px: int) -> tuple[slice, slice]:
    """(rows, cols) slices of the box round a non-empty mask's pixels, grown by ``pad_px``
    and clipped to the grid."""
    (r0, r1), (c0, c1) = (np.flatnonzero(np.any(mask, axis=a))[[0, -1]] for a in (1, 0))
    return (slice(max(r0 - pad_px, 0), r1 + pad_px + 1),
            slice(max(c0 - pad_px, 0), c1 + pad_px + 1))


def _contact_path(rows: IntArray, cols: IntArray, touch: NDArray[np.bool_]) -> IntArray | None:
    """Indices (into rows/cols) of the skeleton path (8-connected) between the two pixels
    touching the tube that lie farthest apart along a skeleton piece; None if the
    piece touches the tube in one place only (no two such pixels 4 px apart)."""
    pts = np.column_stack([rows, cols]).astype(float)
    pairs = cKDTree(pts).query_pairs(1.5, output_type="ndarray")
    if not len(pairs):
        return None
    wt = np.hypot(*(pts[pairs[:, 0]] - pts[pairs[:, 1]]).T)
    n = len(pts)
    graph = csr_matrix((wt, (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    ends = np.nonzero(touch)[0]
    dist, pred = dijkstra(graph, directed=False, indices=ends, return_predecessors=True)
    between = np.where(np.isfinite(dist[:, ends]), dist[:, ends], -1.0)
    i, j = np.unravel_index(np.argmax(between), between.shape)
    if between[i, j] < 4.0:
        return None
    chain = [int(ends[j])]
    while chain[-1] != ends[i]:
        chain.append(int(pred[i, chain[-1]]))
    return np.asarray(chain[::-1], dtype=np.int64)
