"""Orientation-aware minimal path through the snapped clicks, and checks of the result.

The route is a shortest path in a graph whose nodes are (pixel, heading) pairs
for 16 headings, built only on the pixels of a band where the vessel is
(the ridge response around the clicked vessel, not the whole image). A move
goes ``L`` px (2-4, about one lumen radius) along the new heading, which
differs from the current one by at most one step (22.5 deg), so the path's
radius of curvature is at least about 2.5 L and it cannot double back; a turn
inside a crossing costs more (below), so it goes straight through. Each heading
of L = 4 also has moves of 3 px (so every pixel of a narrow band is reachable).
This is a discrete form of the minimal paths in the space of positions and
orientations (Peter et al., "Robust Geodesic Methods on SE(2)", 2015; Bekkers
et al., "A PDE approach to data-driven sub-Riemannian geodesics in SE(2)",
SIAM J. Imaging Sci. 2015).

Cost of a move (summed along its pixels): ``w = ((1 + eps) / (eps + V))^2`` on the
contrast-invariant response V, times ``1 + a V sin^2(heading - vessel direction)``
(moving across a vessel costs more), plus ``b (log sigma_q - log sigma_p)^2`` (scale
continuity: hopping from a small vessel onto a large neighbour costs) and
``c (1 + d J)`` per heading step turned, J the junction measure (a dark blob: a
crossing's centre) near the pixel: inside a crossing the route goes straight.
Solved with ``scipy.sparse.csgraph.dijkstra`` (Dijkstra 1959) from several
start nodes (``min_only``), each search first bounded in cost (its ``limit``) at a few
multiples of the straight distance between the clicks and widened until the cheapest
arrival lies inside the bound: every node that arrival's path could pass through is
then inside it too, so the route is the unbounded search's.

A loop that the route cut across at its crossing is followed round
(:mod:`recon.trace.route_loops`: :func:`loop_apices`, a ring of ridge touching the route
twice; :func:`ring_circuits`, a tight loop's ring, whose hole shows above the band's
level).

A first leg that runs back along itself (a first click on the edge of the band, such
as a branch's bifurcation click on its parent, where no move leads the way the vessel
goes) is solved again from any band pixel within one move of the click.

Checks of a traced centerline (:func:`find_route_problem`): a stretch off the
vessel, a hairpin (the route doubling back) or a stretch that runs over an
earlier part of the route.

Pixels are (col, row), 0-based.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage as ndi
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from recon.trace.guide_catheter import Catheter2D
from recon.trace.route_loops import loop_apices, ring_circuits, route_distance
from recon.trace.trace_error import TraceError
from recon.trace.vesselness import RADIUS_PER_SIGMA, VesselnessMap
from recon.types import arclength

__all__ = ["Route", "minimal_route", "loop_apices", "ring_circuits", "RouteProblem",
           "find_route_problem", "route_distance", "N_HEADINGS"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

N_HEADINGS = 16
#: Floor of the response in the pixel cost (a background pixel costs ~(1/eps)^2).
_EPS = 0.05
#: Extra cost factor of moving straight across a vessel.
_ACROSS = 2.0
#: Cost of one heading step (22.5 deg) turned.
_TURN = 0.3
#: The turn cost is multiplied by 1 + this x the junction measure near the pixel: inside
#: a crossing a route goes straight (a loop is followed round, not cut across), and
#: turns into a branch only where nothing straight leads on.
_JUNCTION_TURN = 30.0
#: Extra cost factor of moving along a guiding catheter (none across it).
_CATHETER_ALONG = 20.0
#: Cost per (change of log scale)^2 between a move's ends.
_SCALE_JUMP = 10.0
#: Move length per lumen radius, at most _MAX_MOVE_PX (the path's radius of curvature
#: is >= ~2.5 moves; longer moves would leave pixels of a narrow band unreachable:
#: the 16 integer moves of length 8 change the row by 0, 3, 6, 7 or 8 only).
_MOVE_PER_RADIUS = 1.0
_MAX_MOVE_PX = 4
#: The route's crop reaches this fraction of the clicks' extent beyond them (a loop
#: or a bend may lie well outside the clicks' box).
_CROP_MARGIN = 1.0
#: A route's search is first bounded at these multiples of _LIMIT_PER_PX x the straight
#: distance between its clicks (a route's cost per px of chord), then without a bound
#: (:meth:`_Graph.solve`; the result is the unbounded search's in every case).
_LIMIT_PER_PX = 2.0
_LIMIT_STEPS = (1.0, 3.0, 12.0)
#: At a waypoint the heading may change by at most this many steps (90 deg).
_WAYPOINT_TURN = 4
#: Loops are looked for in the band and above these multiples of its response level
#: (the ring of a loop about two lumens wide fills in at the band's level).
_RING_LEVELS = (1.0, 1.5, 2.0)


@dataclass(frozen=True)
class Route:
    """A pixel path through the clicks.

    Attributes
    ----------
    path_px : (M, 2) float (col, row), about 1 px apart, first and last = the end clicks.
    click_index : (K,) int, index in ``path_px`` of each click.
    move_px : the move length L (px) of the graph.
    """

    path_px: FloatArray
    click_index: IntArray
    move_px: int


def _headings(move_px: int) -> tuple[IntArray, FloatArray]:
    """Integer moves (16, 2) (dcol, drow) of about ``move_px`` along 16 headings, and
    the headings' angles (16,) in radians."""
    theta = 2.0 * np.pi * np.arange(N_HEADINGS) / N_HEADINGS
    d = np.rint(move_px * np.column_stack([np.cos(theta), np.sin(theta)])).astype(np.int64)
    return d, np.arctan2(d[:, 1], d[:, 0]).astype(float)


def _edge_slots(lengths: tuple[int, ...]) -> IntArray:
    """Slot (C, 16) j C + rank of the edge (length, dk) (C = lengths x dk) of a node (p, j):
    ranked by end node (q, k), i.e. by offset (drow, dcol) in row-major order, then k."""
    k = (np.arange(N_HEADINGS)[:, None] + np.arange(-1, 2)) % N_HEADINGS  # (16, 3)
    d = np.concatenate([_headings(n)[0][k] for n in lengths], axis=1)  # (16, C, 2)
    key = 10_000 * d[..., 1] + 100 * d[..., 0] + np.tile(k, len(lengths))  # (16, C)
    assert np.all(np.diff(np.sort(key, axis=1), axis=1)), "COO would sum duplicate edges"
    return np.argsort(np.argsort(key, axis=1), axis=1).T + key.shape[1] * np.arange(N_HEADINGS)


def _crop_box(clicks_px: FloatArray, shape: tuple[int, int], radius_px: float) -> tuple[int, ...]:
    h, w = shape
    lo, hi = clicks_px.min(axis=0), clicks_px.max(axis=0)
    margin = 20.0 + _CROP_MARGIN * float(np.max(hi - lo)) + 3.0 * radius_px
    c0, r0 = np.maximum(np.floor(lo - margin), 0).astype(int)
    c1 = int(min(np.ceil(hi[0] + margin) + 1, w))
    r1 = int(min(np.ceil(hi[1] + margin) + 1, h))
    return int(r0), int(r1), int(c0), int(c1)


class _Graph:
    """The (pixel, heading) graph on a band of a crop."""

    def __init__(self, band: NDArray[np.bool_], resp: FloatArray, log_scale: FloatArray,
                 direction: FloatArray, move_px: int, junction: FloatArray,
                 catheter: tuple[FloatArray, FloatArray] | None = None) -> None:
        h, w = band.shape
        self.shape = (h, w)
        self.rows, self.cols = np.nonzero(band)
        n = len(self.rows)
        self.index = np.full((h, w), -1, dtype=np.int64)
        self.index[self.rows, self.cols] = np.arange(n)
        # The pixel maps on the band's bounding box only: a move that stays on the band
        # samples only pixels between its ends (:meth:`_moves`).
        self.box = (int(self.rows.min()), int(self.rows.max()) + 1,
                    int(self.cols.min()), int(self.cols.max()) + 1)
        in_box = (slice(self.box[0], self.box[1]), slice(self.box[2], self.box[3]))
        resp, direction = resp[in_box], direction[in_box]
        cost_px = ((1.0 + _EPS) / (_EPS + resp)) ** 2  # (box), 1 on a full-strength ridge
        turn = _TURN * (1.0 + _JUNCTION_TURN * junction[self.rows, self.cols])  # (n,)
        # For L = 4 two move lengths, 4 and 3: integer moves of length 4 alone change
        # the row by 0, 2, 3 or 4 only, and miss pixels of a narrow band (L <= 3 reach
        # all). Their offsets differ, so every (node, node) pair has one edge.
        # sin^2(h - phi) = (1 - cos 2h cos 2phi - sin 2h sin 2phi) / 2
        across = _ACROSS * resp * cost_px / 2.0
        terms = (cost_px + across, -across * np.cos(2 * direction),
                 -across * np.sin(2 * direction))
        if catheter is not None:
            # along a catheter: w K c cos^2(h - psi) = w K c (1 + cos 2h cos 2psi
            # + sin 2h sin 2psi) / 2, c = 1 on its lumen, psi its direction
            c_w, c_dir = (m[in_box] for m in catheter)
            along = _CATHETER_ALONG * c_w * cost_px / 2.0
            terms = (terms[0] + along, terms[1] + along * np.cos(2 * c_dir),
                     terms[2] + along * np.sin(2 * c_dir))
        lengths = (int(move_px),) if move_px <= 3 else (int(move_px), int(move_px) - 1)
        # Edges (p, k - dk) -> (q, k), dk in -1, 0, 1, in scipy's COO-to-CSR order (by end
        # node, fixed per heading: _edge_slots), written (slot, pixel), read transposed.
        slots = _edge_slots(lengths)  # (C, 16)
        m, width = n * N_HEADINGS, slots.size // N_HEADINGS
        dst, ok_all, wt = (np.empty((N_HEADINGS * width, n), dtype=t) for t in (int, bool, float))
        for i, length_px in enumerate(lengths):
            q, ok, move = (a.T.copy() for a in self._moves(length_px, terms, log_scale))
            for dk in (-1, 0, 1):
                k, at = (np.arange(N_HEADINGS) + dk) % N_HEADINGS, slots[3 * i + 1 + dk]
                dst[at], ok_all[at] = q[k] * N_HEADINGS + k[:, None], ok[k]
                wt[at] = move[k] + turn * abs(dk)
        indptr = np.concatenate([[0], np.cumsum(ok_all.reshape(N_HEADINGS, width, n).sum(1).T)])
        indices, data = dst.T[ok_all.T], wt.T[ok_all.T]
        self.graph = csr_matrix((data, indices, indptr), shape=(m, m))
        self.cost_px = cost_px[self.rows - self.box[0], self.cols - self.box[2]]  # (n,)
        # the shortest-path tree of the last search from all of a pixel's headings
        self._last_tree: tuple[tuple[bytes, bytes, float], tuple[FloatArray, IntArray]] | None = \
            None

    def _moves(self, length_px: int, terms: tuple[FloatArray, FloatArray, FloatArray],
               log_scale: FloatArray):
        """For every band pixel and heading, the move of ``length_px``: end node (n, 16)
        (-1 off the band), whether it stays on the band, and its cost (n, 16).

        The pixel cost w (1 + a V sin^2(heading - direction)) is A + B cos 2h + D sin 2h
        with per-pixel maps ``terms`` = (A, B, D) on the band's box; it is averaged at
        the move's middle and end (rounded, they lie between its ends: inside the box
        for a move that stays on the band; the others' costs are not used).
        """
        h, w = self.shape
        r_lo, r_hi, c_lo, c_hi = self.box
        d, theta = _headings(length_px)
        qc = self.cols[:, None] + d[None, :, 0]  # (n, 16)
        qr = self.rows[:, None] + d[None, :, 1]
        inside = (qc >= 0) & (qc < w) & (qr >= 0) & (qr < h)
        q = np.where(inside, self.index[np.clip(qr, 0, h - 1), np.clip(qc, 0, w - 1)], -1)
        ok = q >= 0
        flat = []
        for t in (0.5, 1.0):
            sc = np.clip(np.rint(self.cols[:, None] + t * d[None, :, 0]), c_lo, c_hi - 1)
            sr = np.clip(np.rint(self.rows[:, None] + t * d[None, :, 1]), r_lo, r_hi - 1)
            flat.append(((sr - r_lo) * (c_hi - c_lo) + sc - c_lo).astype(np.int64))  # (n, 16)
        a_map, b_map, d_map = (m.ravel() for m in terms)
        mean = [0.5 * (m[flat[0]] + m[flat[1]]) for m in (a_map, b_map, d_map)]
        per_px = mean[0] + np.cos(2 * theta)[None] * mean[1] + np.sin(2 * theta)[None] * mean[2]
        move = np.hypot(d[:, 0], d[:, 1])[None, :] * per_px
        qq = np.where(ok, q, 0)
        jump = log_scale[self.rows[qq], self.cols[qq]] - log_scale[self.rows, self.cols][:, None]
        return q, ok, move + _SCALE_JUMP * jump**2

    def node_pixels(self, nodes: IntArray) -> tuple[IntArray, IntArray]:
        p = nodes // N_HEADINGS
        return self.rows[p], self.cols[p]

    def solve(self, start_rc: tuple[int, int], headings: IntArray, end_rc: tuple[int, int],
              reach_px: float, start_reach_px: float = 0.0) -> tuple[IntArray | None, int]:
        """Cheapest node chain from the start pixel (any of ``headings``) to a band pixel
        within ``reach_px`` of the end; (None, nearest reached band pixel) if none.

        ``start_reach_px`` > 0: the chain may start at any band pixel within that
        distance of the start pixel (at no cost), so that a start on the edge of the
        band, where the heading it needs has no move, can leave in that heading.
        """
        p0 = self.index[start_rc]
        starts = np.array([p0])
        if start_reach_px > 0:
            d0 = np.hypot(self.rows - start_rc[0], self.cols - start_rc[1])
            starts = np.union1d(starts, np.flatnonzero(d0 <= start_reach_px))
        sources = (starts[:, None] * N_HEADINGS + np.asarray(headings)[None, :]).ravel()
        key = (starts.tobytes(), np.asarray(headings).tobytes())
        d_end = np.hypot(self.rows - end_rc[0], self.cols - end_rc[1])
        near = d_end <= reach_px
        end_cost = (d_end * self.cost_px)[:, None]
        # Searches bounded by a cost limit, raised until the cheapest arrival lies within
        # it (then every node it could come from does, and the bounded search's tree is
        # the full one's there), last without a bound.
        chord_px = float(np.hypot(start_rc[0] - end_rc[0], start_rc[1] - end_rc[1]))
        limits = [_LIMIT_PER_PX * f * (chord_px + reach_px) for f in _LIMIT_STEPS] + [np.inf]
        cached = self._last_tree is not None and self._last_tree[0][:2] == key
        if cached:  # the last tree from here first, then only wider bounds
            have = self._last_tree[0][2]
            limits = [have, *(lim for lim in limits if lim > have)]
        for limit in limits:
            if cached and self._last_tree[0][2] == limit:
                dist, pred = self._last_tree[1]  # a route through apices starts where one did
            else:
                dist, pred, _ = dijkstra(self.graph, directed=True, indices=sources,
                                         min_only=True, return_predecessors=True, limit=limit)
                if len(headings) == N_HEADINGS:
                    self._last_tree = ((*key, limit), (dist, pred))
                    cached = True
            per_pixel = dist.reshape(-1, N_HEADINGS)
            finite = np.isfinite(per_pixel)
            total = np.where(near[:, None] & finite, per_pixel + end_cost, np.inf)
            if np.min(total) <= limit:
                break
        if not np.any(finite[near]):
            reached = np.nonzero(finite.any(axis=1))[0]
            return None, int(reached[np.argmin(d_end[reached])]) if len(reached) else int(p0)
        node = int(np.argmin(total))
        chain = [node]
        while pred[chain[-1]] >= 0:
            chain.append(int(pred[chain[-1]]))
        return np.asarray(chain[::-1], dtype=np.int64), node // N_HEADINGS


def _catheter_maps(catheters: tuple[Catheter2D, ...],
                   crop: tuple[int, int, int, int]) -> tuple[FloatArray, FloatArray]:
    """On the crop (r0, r1, c0, c1): 1 on the lumen of a catheter (its radius + 1 px
    round its centre line), else 0; and its direction (rad, of the (col, row) tangent)
    at the nearest centre-line point."""
    r0, r1, c0, c1 = crop
    weight = np.zeros((r1 - r0, c1 - c0))
    angle = np.zeros_like(weight)
    for cath in catheters:
        pts = cath.points_px - [c0, r0]
        reach = float(cath.radius_px.max()) + 1.0
        lo = np.maximum(np.floor(pts.min(axis=0) - reach), 0).astype(int)
        hi = np.minimum(np.ceil(pts.max(axis=0) + reach) + 1, [c1 - c0, r1 - r0]).astype(int)
        if np.any(hi <= lo):
            continue
        # the centre line every 0.5 px, painted into the box; each box pixel's nearest
        # painted pixel by a distance transform
        s = arclength(pts)
        s_fine = np.arange(0.0, s[-1] + 1e-9, 0.5)
        fine = np.column_stack([np.interp(s_fine, s, pts[:, j]) for j in (0, 1)])
        t = np.gradient(fine, axis=0)
        radius = np.interp(s_fine, s, cath.radius_px)
        ij = np.rint(fine[:, ::-1] - lo[::-1]).astype(int)
        ok = np.all((ij >= 0) & (ij < (hi - lo)[::-1]), axis=1)
        if not np.any(ok):
            continue
        label = np.full(tuple((hi - lo)[::-1]), -1)
        label[ij[ok, 0], ij[ok, 1]] = np.flatnonzero(ok)
        d, near = ndi.distance_transform_edt(label < 0, return_indices=True)
        k = label[near[0], near[1]]
        inside = d <= radius[k] + 1.0
        psi = np.arctan2(t[k, 1], t[k, 0]) % np.pi
        box = (slice(lo[1], hi[1]), slice(lo[0], hi[0]))
        weight[box] = np.where(inside, 1.0, weight[box])
        angle[box] = np.where(inside, psi, angle[box])
    return weight, angle


def _chord_points(a: FloatArray, b: FloatArray) -> FloatArray:
    """Points (n, 2) from a (excluded) to b (included), about 1 px apart."""
    n = max(int(np.ceil(np.hypot(*(b - a)))), 1)
    t = np.arange(1, n + 1)[:, None] / n
    return a[None, :] * (1.0 - t) + b[None, :] * t


def minimal_route(
    vmap: VesselnessMap, clicks_px: FloatArray, *, view: str = "A",
    catheters: tuple[Catheter2D, ...] = (),
) -> Route:
    """Orientation-aware minimal path (module docstring) through the clicks in order.

    Parameters
    ----------
    vmap : the image's vesselness (with ``direction_rad``).
    clicks_px : (K >= 2, 2) snapped clicks (col, row), on the vessel.
    view : view name used in error messages.
    catheters : the image's catheter tubes (:func:`recon.trace.guide_catheter.find_catheters`):
        a move along one costs :data:`_CATHETER_ALONG` times more (crossing one does not).

    Raises
    ------
    TraceError if no band path joins two consecutive clicks (the vessel is
    interrupted); the message names the clicks and the place.
    """
    clicks = np.asarray(clicks_px, dtype=float)
    h, w = vmap.shape
    r_click = vmap.radius_px_at(clicks)
    r_ref = float(np.median(r_click))
    move_px = int(np.clip(np.rint(_MOVE_PER_RADIUS * r_ref), 2, _MAX_MOVE_PX))
    r0, r1, c0, c1 = _crop_box(clicks, (h, w), float(r_click.max()))
    resp = (vmap.response if vmap.ridge is None else vmap.ridge)[r0:r1, c0:c1].astype(float)
    log_scale = np.log(np.maximum(vmap.scale_px[r0:r1, c0:c1].astype(float), 1e-3))
    direction = (np.zeros_like(resp) if vmap.direction_rad is None
                 else vmap.direction_rad[r0:r1, c0:c1].astype(float))
    junction = (np.zeros_like(resp) if vmap.junction is None
                else ndi.grey_dilation(vmap.junction[r0:r1, c0:c1].astype(float),
                                       size=max(3, 2 * int(round(r_ref)) + 1)))
    cath_w, cath_dir = _catheter_maps(catheters, (r0, r1, c0, c1))
    local = clicks - [c0, r0]
    rc = [(int(np.clip(np.rint(p[1]), 0, r1 - r0 - 1)), int(np.clip(np.rint(p[0]), 0, c1 - c0 - 1)))
          for p in local]
    # The band: pixels responding at least half as strongly as the clicked vessel
    # (relative to the clicks, not to the image), and the clicks themselves.
    v_click = np.array([resp[r, c] for r, c in rc])
    tau = float(np.clip(0.5 * v_click.min(), 0.05, 0.5))
    core = resp >= tau
    seeds = np.zeros_like(core)
    for r, c in rc:
        seeds[max(r - 1, 0) : r + 2, max(c - 1, 0) : c + 2] = True
    last_err: TraceError | None = None
    for grow in (0, 2, 6):  # widen the band when a faint stretch breaks it
        band = (ndi.binary_dilation(core, iterations=grow) if grow else core) | seeds
        labels, _ = ndi.label(band, structure=np.ones((3, 3)))
        keep = np.unique([labels[r, c] for r, c in rc])
        band = np.isin(labels, keep[keep > 0])  # only the pieces the clicks are on
        graph = _Graph(band, resp, log_scale, direction, move_px, junction,
                       (cath_w, cath_dir))
        try:
            route = _route_on(graph, local, rc, move_px, (c0, r0), view, r_ref)
        except TraceError as err:
            last_err = err
            continue
        lumen_px = radius_from_scale(vmap.scale_px[r0:r1, c0:c1])
        # A tight loop's ring may show its hole only above the band's level.
        rings = [band & (resp >= f * tau) for f in _RING_LEVELS]
        return _round_loops(route, graph, rings, lumen_px, local, move_px, (c0, r0), view,
                            r_ref)
    assert last_err is not None
    raise last_err


def _route_on(graph: _Graph, local: FloatArray, rc: list[tuple[int, int]], move_px: int,
              origin: tuple[int, int], view: str, radius_px: float,
              no_fold: frozenset[int] = frozenset()) -> Route:
    """The route through the clicks ``local`` (K, 2) in order; at the waypoints whose
    indices are in ``no_fold`` the route may not turn by more than 90 degrees."""
    pieces = [local[:1]]
    click_index = [0]
    headings = np.arange(N_HEADINGS)
    for i in range(len(local) - 1):
        chain, last = graph.solve(rc[i], headings, rc[i + 1], reach_px=float(move_px))
        leg = None
        if i == 0 and chain is not None:
            leg = _leg_points(graph, chain, rc[0], local[0], local[1])
            if _retraces(leg, radius_px):
                # A first click on the edge of the band (a bifurcation click on its
                # parent's edge) from which no move leads towards the vessel: the route
                # wheeled round somewhere and came back. It may start within one move.
                near_start, _ = graph.solve(rc[0], headings, rc[1], float(move_px),
                                            start_reach_px=float(move_px))
                if near_start is not None:
                    chain, leg = near_start, None
        if chain is None and i > 0 and i not in no_fold:
            # Reachable only by turning at the waypoint: a vessel that folds back in
            # projection (foreshortened) turns there too, so the turn is allowed; clicks
            # out of order show as a route that runs back over itself (checked below).
            chain, _ = graph.solve(rc[i], np.arange(N_HEADINGS), rc[i + 1], float(move_px))
        if chain is None:
            near = np.array([graph.cols[last], graph.rows[last]], float) + origin
            raise TraceError(
                f"view {view}: no vessel path between click {i + 1} and click {i + 2}: the "
                f"vessel is interrupted after ({near[0]:.0f}, {near[1]:.0f}); add a waypoint "
                "where it continues, or check that both clicks are on the same vessel",
                view=view, near_px=near,
            )
        if leg is None:
            leg = _leg_points(graph, chain, rc[i], local[i], local[i + 1])
        new = [leg] if len(leg) else []
        if i > 0 and new and _turns_back(np.concatenate(pieces), np.concatenate(new),
                                         radius_px):
            near = local[i] + np.asarray(origin, float)
            raise TraceError(
                f"view {view}: the trace doubles back at click {i + 1} "
                f"({near[0]:.0f}, {near[1]:.0f}): click {i + 2} lies back along the "
                f"vessel; put the clicks in order along the vessel (if they are, the "
                f"vessel folds back on itself in this view: choose another view)",
                view=view, near_px=near,
            )
        pieces.extend(new)
        click_index.append(sum(len(p) for p in pieces) - 1)
        k_end = int(chain[-1] % N_HEADINGS)
        steps = np.arange(-_WAYPOINT_TURN, _WAYPOINT_TURN + 1)
        headings = (k_end + steps) % N_HEADINGS
    path = np.concatenate(pieces) + np.asarray(origin, float)
    return Route(path_px=path, click_index=np.asarray(click_index, dtype=np.int64),
                 move_px=move_px)


def _leg_points(graph: _Graph, chain: IntArray, start_rc: tuple[int, int], start: FloatArray,
                end: FloatArray) -> FloatArray:
    """The points (n, 2), about 1 px apart, of a leg's node chain from the click ``start``
    (2,) (excluded) to ``end`` (2,); a chain that starts on another pixel than the
    click's is joined to the click by a chord."""
    rows, cols = graph.node_pixels(chain)
    pts = np.column_stack([cols, rows]).astype(float)
    if (int(rows[0]), int(cols[0])) == start_rc:
        pts[0] = start
    else:
        pts = np.vstack([start, pts])
    pts = np.vstack([pts, end])
    legs = [_chord_points(a, b) for a, b in zip(pts[:-1], pts[1:], strict=True)
            if np.hypot(*(b - a)) > 1e-9]
    return np.concatenate(legs) if legs else np.empty((0, 2))


def _round_loops(route: Route, graph: _Graph, rings: list[NDArray[np.bool_]],
                 lumen_px: FloatArray, local: FloatArray, move_px: int,
                 origin: tuple[int, int], view: str, radius_px: float) -> Route:
    """The route with every loop it cut across followed round.

    Loops are sought in the ``rings`` masks (the band at rising response levels), the
    first that shows one. A loop found by :func:`loop_apices` has its apex made a
    waypoint that the route passes without turning back; the route without it is
    kept if that fails, if the new route doubles back or runs over itself
    (:func:`find_route_problem`), or if it runs back along itself (then it went into
    a branch and back). Failing that, a tight loop's ring (:func:`ring_circuits`, in the
    masks above the band's level: a hole the band itself shows is no tight loop's, and
    between a vessel, a branch and a crossing vessel it often is one) is spliced into
    the route at its crossing (:func:`_spliced`).
    """
    o = np.asarray(origin, float)
    route_dist = route_distance(rings[0].shape, route.path_px - o)
    for ring_band in rings:
        loops = loop_apices(ring_band, route.path_px - o, radius_px, lumen_px,
                            route_dist_px=route_dist)
        if loops:
            break
    else:
        for ring_band in rings[1:]:  # a hole that shows only above the band's level
            circuits = ring_circuits(ring_band, route.path_px - o, radius_px)
            if circuits:
                return _spliced(route, circuits, o, radius_px)
        return route
    at = [int(np.clip(np.searchsorted(route.click_index, index, side="right"), 1,
                      len(local) - 1)) for index, _ in loops]  # after the click before
    apices = [apex for _, apex in loops]
    looped = _through_apices(graph, local, at, apices, move_px, origin, view, radius_px)
    return route if looped is None else looped


def _spliced(route: Route, circuits: list[tuple[int, FloatArray]], origin: FloatArray,
             radius_px: float) -> Route:
    """The route with each ring circuit (:func:`ring_circuits`, crop pixels) spliced in
    at its crossing; the route as it was if the result doubles back or runs over
    itself (:func:`find_route_problem`)."""
    pieces, index = [], np.asarray(route.click_index).copy()
    start = 0
    for i, circuit in circuits:
        pieces += [route.path_px[start : i + 1], circuit + origin]
        index[index > i] += len(circuit)
        start = i + 1
    pieces.append(route.path_px[start:])
    path = np.concatenate(pieces)
    if find_route_problem(path, np.full(len(path), radius_px), np.ones(len(path), bool)):
        return route
    return Route(path_px=path, click_index=index, move_px=route.move_px)


def _through_apices(graph: _Graph, local: FloatArray, at: list[int], apices: list[FloatArray],
                    move_px: int, origin: tuple[int, int], view: str,
                    radius_px: float) -> Route | None:
    """The route through the clicks ``local`` (K, 2) with each apex (2,) inserted before
    click ``at[i]`` (1 <= at <= K - 1) as a waypoint it may not fold back at; None if
    there is none, if it doubles back or runs over itself (:func:`find_route_problem`),
    or if it runs back along itself (into a branch and back)."""
    clicks = list(local)
    is_click = [True] * len(local)
    # From the last insertion point back, so the earlier positions stay valid; apices
    # before the same click keep their order.
    for pos, apex in reversed(sorted(zip(at, apices, strict=True), key=lambda a: a[0])):
        clicks.insert(pos, apex)
        is_click.insert(pos, False)
    pts = np.array(clicks)
    rc = [(int(p[1]), int(p[0])) for p in np.rint(pts)]
    keep = np.asarray(is_click, dtype=bool)
    try:
        looped = _route_on(graph, pts, rc, move_px, origin, view, radius_px,
                           no_fold=frozenset(np.nonzero(~keep)[0].tolist()))
    except TraceError:
        return None
    path = looped.path_px
    if find_route_problem(path, np.full(len(path), radius_px), np.ones(len(path), bool)):
        return None
    if _retraces(path, radius_px):
        return None
    return Route(path_px=looped.path_px, click_index=looped.click_index[keep],
                 move_px=looped.move_px)


def _retraces(path_px: FloatArray, radius_px: float) -> bool:
    """Whether a route (M, 2), about 1 px apart, runs back along itself: more than
    4 r + 4 px of it lies within 2 r of a part of it more than 2 r + 4 px of route
    away, heading the opposite way (into a branch and back; a loop's second pass
    crosses its first at an angle)."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path_px, axis=0), axis=1))])
    pairs = cKDTree(path_px).query_pairs(max(2.0 * radius_px, 1.5), output_type="ndarray")
    if not len(pairs):
        return False
    i, j = pairs[:, 0], pairs[:, 1]
    t = np.gradient(path_px, axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    back = (np.abs(s[j] - s[i]) > 2.0 * radius_px + 4.0) & \
        (np.einsum("ij,ij->i", t[i], t[j]) < -0.7)
    marked = np.zeros(len(path_px), dtype=bool)
    marked[i[back]] = True
    step = float(np.median(np.diff(s))) if len(s) > 1 else 1.0
    return any((b - a) * step > 4.0 * radius_px + 4.0 for a, b in _runs(marked))


def _turns_back(before: FloatArray, after: FloatArray, radius_px: float) -> bool:
    """Whether the route after a waypoint (M, 2) runs back along the route before it
    (N, 2): more than max(3 r, 6) px of it, beyond 2 r + 4 px of the waypoint, lies
    within max(1.5, r) px of the earlier route heading the opposite way (a loop's
    second pass crosses its first, it does not retrace it)."""
    lead = np.cumsum(np.r_[0.0, np.linalg.norm(np.diff(after, axis=0), axis=1)])
    far = lead > 2.0 * radius_px + 4.0
    if not np.any(far) or len(before) < 2:
        return False
    d, j = cKDTree(before).query(after[far])
    t_before = np.gradient(before, axis=0)
    t_after = np.gradient(after, axis=0)[far] if len(after) > 1 else np.zeros((1, 2))
    cos = np.einsum("ij,ij->i", t_after, t_before[j]) / np.maximum(
        np.linalg.norm(t_after, axis=1) * np.linalg.norm(t_before[j], axis=1), 1e-12)
    back = (d <= max(1.5, radius_px)) & (cos < -0.5)
    step = float(np.median(np.diff(lead))) if len(lead) > 1 else 1.0
    return float(np.count_nonzero(back)) * step > max(3 * radius_px, 6.0)


# ------------------------------------------------------------------- checks
@dataclass(frozen=True)
class RouteProblem:
    """What is wrong with a traced centerline, and where.

    kind : "leaves the vessel", "doubles back" or "runs back over itself".
    index : index of the point (in the checked centerline) nearest the place.
    """

    kind: str
    index: int


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """(start, stop) index ranges of the True runs of a 1-D mask."""
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.diff(m)
    return list(zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0], strict=True))


def find_route_problem(
    points_px: FloatArray, radius_px: FloatArray, on_vessel: NDArray[np.bool_]
) -> RouteProblem | None:
    """The first problem of a centerline (N, 2) at uniform arc length, or None.

    Parameters
    ----------
    points_px : (N, 2) centerline (col, row), uniform spacing.
    radius_px : (N,) fitted lumen radius.
    on_vessel : (N,) bool, where the centerline lies on a dark ridge.

    Returns
    -------
    RouteProblem for the first of: a stretch off the vessel longer than
    max(2 r, 4 px); a hairpin (the heading reverses within max(8 r, 20) px of arc
    while the ends stay within a third of that); a stretch longer than
    max(6 r, 12 px) that lies within max(1.5, 0.7 r) px of a part of the route
    more than 6 r + 6 px of arc away (a transversal crossing of a loop is shorter).
    """
    n = len(points_px)
    if n < 4:
        return None
    step = float(np.median(np.linalg.norm(np.diff(points_px, axis=0), axis=1)))
    step = max(step, 1e-6)
    r_ref = float(np.median(radius_px))
    # Off the vessel.
    min_off = max(2.0 * r_ref, 4.0) / step
    for a, b in _runs(~np.asarray(on_vessel, bool)):
        if b - a > min_off:
            return RouteProblem("leaves the vessel", int((a + b) // 2))
    # Doubling back: the heading reverses within a short arc.
    t = np.gradient(points_px, axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    win = int(max(8.0 * r_ref, 20.0) / step)
    if win < n:
        lags = np.arange(max(int(2.0 / step), 1), win + 1)
        i = np.arange(n)[:, None]
        j = np.minimum(i + lags[None, :], n - 1)
        dots = np.einsum("nlk,nlk->nl", np.broadcast_to(t[:, None, :], (n, len(lags), 2)), t[j])
        chord = np.linalg.norm(points_px[j] - points_px[:, None, :], axis=2)
        hair = (dots < -0.7) & (chord < (lags[None, :] * step) / 3.0) & (i + lags[None, :] < n)
        if np.any(hair):
            ii, ll = np.nonzero(hair)
            k = int(np.argmin(dots[ii, ll]))
            return RouteProblem("doubles back", int(ii[k] + lags[ll[k]] // 2))
    # Running over an earlier part of the route.
    close = max(1.5, 0.7 * r_ref)
    pairs = cKDTree(points_px).query_pairs(close, output_type="ndarray")
    if len(pairs):
        far = np.abs(pairs[:, 1] - pairs[:, 0]) * step > 6.0 * r_ref + 6.0
        over = np.zeros(n, dtype=bool)
        over[pairs[far].ravel()] = True
        min_over = max(6.0 * r_ref, 12.0) / step
        for a, b in _runs(over):
            if b - a > min_over:
                return RouteProblem("runs back over itself", int((a + b) // 2))
    return None


def radius_from_scale(scale_px: FloatArray) -> FloatArray:
    """Lumen radius (px) of a vessel whose best Hessian scale is ``scale_px``."""
    return RADIUS_PER_SIGMA * np.asarray(scale_px, dtype=float)
