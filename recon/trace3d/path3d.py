"""The vessel's 3D centreline as a minimal path that both views vote on.

A 3D point X costs little where its projections lie on vessel in both views
(:class:`~recon.trace3d.evidence.ViewEvidence`), and a great deal where either view
shows no vessel there. The path runs from the triangulated proximal click to the
triangulated distal click and crosses the ray of every waypoint (a waypoint clicked
in one view is a ray in 3D). It is found by Dijkstra's algorithm on a voxel graph
(26 neighbours), coarse then fine:

    anchors: triangulate the end clicks (refuse ends whose rays miss each other)
      -> coarse grid (COARSE_MM) over the box around the anchors, kept only where
         both views show vessel (the back-projected masks meet in a thin set)
      -> minimal path through the waypoints' rays (one copy of the graph per
         number of waypoints passed in each view)
      -> fine grid (FINE_MM) in a tube around the coarse path, the same search
      -> a smoothing spline through the voxel centres, at STEP_MM.

The point cost is (eq. numbers are this module's own, the method is not the paper's)::

    c(X) = C0 + sum_k -log(EPS + s_k(P_k X)) + W_SCALE |log(r_A(X) / r_B(X))|

with s_k the view's support in [0, 1] and r_k the vessel radius (mm at the point's
depth) that each view reads there: a neighbour or the other limb of a loop that is
on vessel in one view only costs -log(EPS) there, and a vessel of another calibre
costs its scale mismatch. View B's support is read at the best of a few places across
its epipolar line, up to the pose's remaining error (``tol_px``): along the epipolar
line a pose error is only a change of depth, across it is a real disagreement.

Where the path's image in B runs along B's epipolar lines, a sideways jump in one view
is invisible in the other: those stretches are returned flagged.

The approach is that of 3D front propagation on back-projected vesselness (Jandt et
al., Med Image Anal 13, 2009) with two views, the sparse case.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage as ndi
from scipy import sparse
from scipy.interpolate import splev, splprep
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from recon.geometry import ViewGeometry, ray_distance_mm, triangulate
from recon.trace.trace_error import TraceError
from recon.trace3d.evidence import ViewEvidence

__all__ = ["Path3D", "trace_path_3d", "COARSE_MM", "FINE_MM"]

FloatArray = NDArray[np.float64]

#: Voxel size (mm) of the coarse search, and of the fine one.
COARSE_MM = 2.0
FINE_MM = 0.5
#: Radius (mm) of the fine search's tube around the coarse path.
TUBE_MM = 3.0
#: Spacing (mm) of the returned path.
STEP_MM = 0.5
#: The box around the anchors: at least this margin (mm), or this fraction of the chord.
MARGIN_MM = 15.0
MARGIN_FRACTION = 0.45
#: Least support (per view) for a voxel to be searched at all.
MIN_SUPPORT = 0.15
#: Cost terms (see the module docstring).
C0 = 0.05
EPS = 0.02
W_SCALE = 2.5
#: A path may start (end) where both views see it within this (px) of the end clicks.
END_PX = 3.0
#: End rays further apart than this (mm) are clicks on different vessels.
MAX_END_RAY_MM = 4.0
#: A stretch runs along the epipolar lines where |cos| of the angle between the path's
#: direction in B and the epipolar line exceeds this, over at least ALONG_MIN_MM.
ALONG_COS = 0.95
ALONG_MIN_MM = 3.0

_OFFSETS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                     if (i, j, k) != (0, 0, 0)], dtype=np.int64)


@dataclass(frozen=True)
class Path3D:
    """The 3D path between the clicked ends.

    Attributes
    ----------
    X_world : (M, 3) mm, proximal first, about STEP_MM apart (smoothed).
    s_mm : (M,) arc length.
    support_a, support_b : (M,) each view's support at the path's projections.
    along_epipolar : (M,) bool, stretches whose image in B runs along B's epipolar
        lines (a sideways error in A would not show in B there).
    coarse_nodes, fine_nodes : sizes of the two graphs (for the benchmarks).
    """

    X_world: FloatArray
    s_mm: FloatArray
    support_a: FloatArray
    support_b: FloatArray
    along_epipolar: NDArray[np.bool_]
    coarse_nodes: int
    fine_nodes: int

    def projected(self, view: ViewGeometry) -> FloatArray:
        """The path's image (M, 2) px in ``view``."""
        return view.project(self.X_world)


def _anchors(clicks_a: FloatArray, clicks_b: FloatArray, view_a: ViewGeometry,
             view_b: ViewGeometry) -> tuple[FloatArray, FloatArray]:
    """Triangulated proximal and distal ends (3,) each; refuses ends on different vessels."""
    ends_a, ends_b = clicks_a[[0, -1]], clicks_b[[0, -1]]
    gap_mm = ray_distance_mm(ends_a, ends_b, view_a, view_b)
    for i, role in enumerate(("proximal", "distal")):
        if gap_mm[i] > MAX_END_RAY_MM:
            raise TraceError(
                f"the {role} end clicks of views A and B do not meet in 3D (their rays pass "
                f"{gap_mm[i]:.1f} mm apart): they seem to lie on different vessels; move the "
                f"{role} click in view B onto the vessel clicked in view A",
                view="B", near_px=ends_b[i])
    X = triangulate(ends_a, ends_b, view_a, view_b)
    return X[0], X[1]


def _sample(image: NDArray, points_px: FloatArray) -> FloatArray:
    """Bilinear values (N,) of ``image`` at (col, row) points (N, 2), 0 outside."""
    return ndi.map_coordinates(image, [points_px[:, 1], points_px[:, 0]], order=1,
                               mode="constant", cval=0.0)


def _across_epipolar(view_b: ViewGeometry, epipole_b: FloatArray, p_b: FloatArray,
                     tol_px: float) -> list[FloatArray]:
    """Points (N, 2) in B at offsets of up to ``tol_px`` across the epipolar line of each."""
    if tol_px <= 0:
        return [p_b]
    d = p_b - epipole_b
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    n = np.column_stack([-d[:, 1], d[:, 0]])
    steps = np.linspace(-tol_px, tol_px, 2 * int(np.ceil(tol_px)) + 1)
    return [p_b + t * n for t in steps]


def _point_costs(X: FloatArray, p_a: FloatArray, p_b: FloatArray, view_a: ViewGeometry,
                 view_b: ViewGeometry, ev_a: ViewEvidence, ev_b: ViewEvidence,
                 epipole_b: FloatArray, tol_px: float,
                 coarse: bool) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Cost (N,) of world points X (N, 3), seen at p_a, p_b (N, 2) in the views, and
    whether both views support them (N,)."""
    sup_a_map = ev_a.support_coarse if coarse else ev_a.support
    sup_b_map = ev_b.support_coarse if coarse else ev_b.support
    s_a = _sample(sup_a_map, p_a)
    cands = _across_epipolar(view_b, epipole_b, p_b, tol_px)
    s_bs = np.stack([_sample(sup_b_map, q) for q in cands])
    best = np.argmax(s_bs, axis=0)
    s_b = s_bs[best, np.arange(len(X))]
    q_b = np.stack(cands)[best, np.arange(len(X))]
    ok = (s_a > MIN_SUPPORT) & (s_b > MIN_SUPPORT)
    # each view's radius in mm at the point's depth
    r_a = _sample(ev_a.radius_px, p_a) * view_a.pixel_spacing_mm[1] * \
        view_a.depth_mm(X) / view_a.sid_mm
    r_b = _sample(ev_b.radius_px, q_b) * view_b.pixel_spacing_mm[1] * \
        view_b.depth_mm(X) / view_b.sid_mm
    scale = np.abs(np.log(np.maximum(r_a, 0.05) / np.maximum(r_b, 0.05)))
    cost = C0 - np.log(EPS + s_a) - np.log(EPS + s_b) + W_SCALE * scale
    return cost, ok


def _box(anchors: list[FloatArray]) -> tuple[FloatArray, FloatArray]:
    """Lower and upper corners (3,) of the search box around the anchors."""
    P = np.asarray(anchors)
    chord = float(np.linalg.norm(P[-1] - P[0]))
    margin = max(MARGIN_MM, MARGIN_FRACTION * chord)
    return P.min(axis=0) - margin, P.max(axis=0) + margin


def _grid_edges(ijk: NDArray[np.int64], cost: FloatArray, step_mm: float
                ) -> tuple[NDArray[np.int64], NDArray[np.int64], FloatArray]:
    """The 26-neighbour edges (each once) over voxels ijk (N, 3): (from, to, weight),
    weight = length x mean point cost."""
    lo = ijk.min(axis=0)
    dims = ijk.max(axis=0) - lo + 3
    index = np.full(tuple(dims), -1, dtype=np.int64)
    local = ijk - lo + 1
    index[local[:, 0], local[:, 1], local[:, 2]] = np.arange(len(ijk))
    rows, cols, weights = [], [], []
    for off in _OFFSETS:
        if tuple(off) < (0, 0, 0):
            continue  # each undirected edge once
        nb = local + off
        j = index[nb[:, 0], nb[:, 1], nb[:, 2]]
        have = j >= 0
        i = np.nonzero(have)[0]
        rows.append(i)
        cols.append(j[have])
        weights.append(step_mm * np.linalg.norm(off) * 0.5 * (cost[i] + cost[j[have]]))
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(weights)


def _layered_path(n: int, edges: tuple[NDArray[np.int64], NDArray[np.int64], FloatArray],
                  starts: NDArray[np.bool_], ends: NDArray[np.bool_],
                  gates_a: list[NDArray[np.bool_]], gates_b: list[NDArray[np.bool_]]
                  ) -> tuple[NDArray[np.int64], float]:
    """Node indices of the cheapest path over the graph of ``n`` nodes and undirected
    ``edges`` from a ``starts`` node to an ``ends`` node (N,) bool that passes every gate,
    and its cost.

    ``gates_a``, ``gates_b``: per view, in the order the path must pass them, the nodes
    (N,) bool near each of the view's waypoint rays. A's and B's waypoints are each
    ordered along the vessel, but not one against the other, so the graph is copied once
    per (A gates passed, B gates passed); crossing from a copy to the next is free at the
    next gate's nodes. A source joins every start node of the first copy, a sink every end
    node of the last.
    """
    r0, c0, w0 = edges
    na, nb = len(gates_a) + 1, len(gates_b) + 1
    n_layers = na * nb
    src, snk = n_layers * n, n_layers * n + 1
    # one layer's symmetric graph, then its copies as a block diagonal built from its CSR
    # arrays (the copies' rows follow each other: no sort of the whole graph)
    one = sparse.csr_matrix((np.concatenate([w0, w0]), (np.concatenate([r0, c0]),
                                                         np.concatenate([c0, r0]))),
                            shape=(n, n))
    layers = np.arange(n_layers)
    indptr = np.concatenate([(one.indptr[:-1][None, :] + one.nnz * layers[:, None]).ravel(),
                             np.full(3, n_layers * one.nnz)])
    blocks = sparse.csr_matrix((np.tile(one.data, n_layers),
                                (one.indices[None, :] + n * layers[:, None]).ravel(), indptr),
                               shape=(snk + 1, snk + 1))
    hop_r, hop_c = [np.full(int(starts.sum()), src)], [np.nonzero(starts)[0]]
    hop_r.append((n_layers - 1) * n + np.nonzero(ends)[0])
    hop_c.append(np.full(int(ends.sum()), snk))
    for ia in range(na):
        for ib in range(nb):
            here = (ia * nb + ib) * n
            if ia + 1 < na:
                at = np.nonzero(gates_a[ia])[0]
                hop_r.append(here + at)
                hop_c.append(((ia + 1) * nb + ib) * n + at)
            if ib + 1 < nb:
                at = np.nonzero(gates_b[ib])[0]
                hop_r.append(here + at)
                hop_c.append((ia * nb + ib + 1) * n + at)
    hr, hc = np.concatenate(hop_r), np.concatenate(hop_c)
    graph = blocks + sparse.csr_matrix((np.full(len(hr), 1e-9), (hr, hc)),
                                       shape=(snk + 1, snk + 1))
    dist, pred = dijkstra(graph, directed=True, indices=src, return_predecessors=True)
    if not np.isfinite(dist[snk]):
        raise _NoPath
    chain = [int(pred[snk])]
    while pred[chain[-1]] != src:
        chain.append(int(pred[chain[-1]]))
    return np.asarray(chain[::-1], dtype=np.int64) % n, float(dist[snk])


class _NoPath(Exception):
    """No path through both views' vessel between the anchors."""


def _gates(p: FloatArray, clicks: FloatArray, radius_px: float) -> list[NDArray[np.bool_]]:
    """Per waypoint of one view (its clicks between the ends), the points seen at p (N, 2)
    in that view within ``radius_px`` of it (its ray, widened to the grid)."""
    gates = []
    for w in clicks[1:-1]:
        d = np.linalg.norm(p - w, axis=1)
        near = d <= radius_px
        gates.append(near if np.any(near) else d <= 2.0 * radius_px)
    return gates


def _smooth(X: FloatArray, spacing_mm: float, step_mm: float) -> FloatArray:
    """A smoothing spline through voxel centres X (N, 3), resampled every ``step_mm``."""
    keep = np.concatenate([[True], np.linalg.norm(np.diff(X, axis=0), axis=1) > 1e-9])
    X = X[keep]
    if len(X) < 4:
        t = np.linspace(0.0, 1.0, max(int(np.linalg.norm(X[-1] - X[0]) / step_mm), 2))
        return X[0] + t[:, None] * (X[-1] - X[0])
    seg = np.linalg.norm(np.diff(X, axis=0), axis=1)
    u = np.concatenate([[0.0], np.cumsum(seg)])
    w = np.ones(len(X))
    w[[0, -1]] = 100.0  # the anchors hold
    tck, _ = splprep(X.T, u=u / u[-1], w=w, s=len(X) * (0.35 * spacing_mm) ** 2, k=3)
    dense = np.column_stack(splev(np.linspace(0, 1, 8 * len(X)), tck))
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))])
    n = max(int(np.ceil(s[-1] / step_mm)) + 1, 2)
    at = np.linspace(0.0, s[-1], n)
    return np.column_stack([np.interp(at, s, dense[:, d]) for d in range(3)])


@dataclass(frozen=True, eq=False)
class _Nodes:
    """One grid's candidate voxels: positions X (N, 3), grid indices ijk (N, 3), their
    images p_a, p_b (N, 2), point costs (N,) and whether both views support them (N,)."""

    X: FloatArray
    ijk: NDArray[np.int64]
    p_a: FloatArray
    p_b: FloatArray
    cost: FloatArray
    ok: NDArray[np.bool_]
    step_mm: float


def _nodes(X: FloatArray, ijk: NDArray[np.int64], step_mm: float, view_a: ViewGeometry,
           view_b: ViewGeometry, ev_a: ViewEvidence, ev_b: ViewEvidence, epipole_b: FloatArray,
           tol_px: float, coarse: bool) -> _Nodes:
    """The candidate voxels X (N, 3) with their images and costs."""
    p_a, p_b = view_a.project(X), view_b.project(X)
    cost, ok = _point_costs(X, p_a, p_b, view_a, view_b, ev_a, ev_b, epipole_b, tol_px, coarse)
    return _Nodes(X, ijk, p_a, p_b, cost, ok, step_mm)


def _search(nodes: _Nodes, px_mm: float, tol_px: float, clicks_a: FloatArray,
            clicks_b: FloatArray, anchors: tuple[FloatArray, FloatArray],
            forbidden: NDArray[np.bool_] | None = None) -> tuple[FloatArray, int, float]:
    """The cheapest voxel path (P, 3) between the end clicks over the supported voxels (but
    the ``forbidden`` ones), the number of nodes searched, and the path's cost.

    The ends: voxels seen within END_PX of both end clicks (the nearest voxel to the
    triangulated click when none is), always searched. ``px_mm``: A's pixel at the
    isocentre (mm).
    """
    ok = nodes.ok.copy()
    if forbidden is not None:
        ok &= ~forbidden
    end_px = max(END_PX, 0.75 * nodes.step_mm / px_mm)
    sets = []
    for k, anchor in enumerate(anchors):
        at = 0 if k == 0 else -1
        near = (np.linalg.norm(nodes.p_a - clicks_a[at], axis=1) <= end_px) & \
            (np.linalg.norm(nodes.p_b - clicks_b[at], axis=1) <= end_px + tol_px)
        if not np.any(near):
            near[int(np.argmin(np.linalg.norm(nodes.X - anchor, axis=1)))] = True
        ok |= near
        sets.append(near)
    keep = np.nonzero(ok)[0]
    radius_px = max(2.0, 1.5 * nodes.step_mm / px_mm)
    chain, total = _layered_path(len(keep), _grid_edges(nodes.ijk[keep], nodes.cost[keep],
                                                         nodes.step_mm),
                                 sets[0][keep], sets[1][keep],
                                 _gates(nodes.p_a[keep], clicks_a, radius_px),
                                 _gates(nodes.p_b[keep], clicks_b, radius_px))
    return nodes.X[keep][chain], len(keep), total


def trace_path_3d(
    ev_a: ViewEvidence,
    ev_b: ViewEvidence,
    view_a: ViewGeometry,
    view_b: ViewGeometry,
    clicks_a_px: FloatArray,
    clicks_b_px: FloatArray,
    tol_px: float = 1.5,
) -> Path3D:
    """The vessel's 3D path between the clicked ends, through the waypoints' rays.

    Parameters
    ----------
    ev_a, ev_b : each view's vessel evidence (:func:`recon.trace3d.evidence.view_evidence`).
    view_a, view_b : the calibrated geometries (view B after calibration on the clicks).
    clicks_a_px, clicks_b_px : (K, 2), (L, 2) each view's clicks (col, row), snapped,
        proximal end first, distal end last, waypoints between.
    tol_px : the pose's remaining error in B (px), searched across B's epipolar lines.

    Raises
    ------
    TraceError when the end clicks do not triangulate (different vessels) or when no
    path has vessel support in both views (the message names the view).
    """
    clicks_a = np.asarray(clicks_a_px, dtype=float).reshape(-1, 2)
    clicks_b = np.asarray(clicks_b_px, dtype=float).reshape(-1, 2)
    X0, X1 = _anchors(clicks_a, clicks_b, view_a, view_b)
    epipole_b = view_b.project(view_a.source_world[None, :])[0]

    # Coarse: the box around the anchors, kept where both views show vessel.
    lo, hi = _box([X0, X1])
    axes = [np.arange(lo[d], hi[d] + COARSE_MM, COARSE_MM) for d in range(3)]
    ijk = np.stack(np.meshgrid(*[np.arange(len(a)) for a in axes], indexing="ij"),
                   axis=-1).reshape(-1, 3)
    X_grid = lo + ijk * COARSE_MM
    sel = _supported(view_a, X_grid, ev_a)
    sel[sel] = _supported(view_b, X_grid[sel], ev_b)
    px_mm = view_a.pixel_mm_at_isocenter
    coarse_nodes = _nodes(X_grid[sel], ijk[sel], COARSE_MM, view_a, view_b, ev_a, ev_b,
                          epipole_b, tol_px, coarse=True)

    try:
        coarse, n_coarse, _ = _search(coarse_nodes, px_mm, tol_px, clicks_a, clicks_b, (X0, X1))
    except _NoPath:
        raise _no_support(clicks_a, clicks_b, view_a, view_b, ev_a, ev_b, X0, X1) from None

    # Fine: a tube around the coarse path.
    X_f, ijk_f = _tube(coarse, TUBE_MM, FINE_MM)
    try:
        fine_nodes = _nodes(X_f, ijk_f, FINE_MM, view_a, view_b, ev_a, ev_b,
                            epipole_b, tol_px, coarse=False)
        fine, n_fine, _ = _search(fine_nodes, px_mm, tol_px, clicks_a, clicks_b, (X0, X1))
    except _NoPath:
        fine, n_fine = coarse, 0
    X = _smooth(fine, FINE_MM, STEP_MM)
    s_mm = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(X, axis=0), axis=1))])
    p_a, p_b = view_a.project(X), view_b.project(X)
    return Path3D(
        X_world=X,
        s_mm=s_mm,
        support_a=_sample(ev_a.support, p_a),
        support_b=_sample(ev_b.support, p_b),
        along_epipolar=_along_epipolar(p_b, epipole_b, s_mm),
        coarse_nodes=n_coarse,
        fine_nodes=n_fine,
    )


def _supported(view: ViewGeometry, X: FloatArray, ev: ViewEvidence) -> NDArray[np.bool_]:
    """Whether points X (N, 3) project inside the view's field onto some vessel support
    (the coarse map at the nearest pixel above MIN_SUPPORT): the cheap first cut."""
    p = view.project(X)
    h, w = ev.support.shape
    q = np.rint(p).astype(np.int64)
    inside = (q[:, 0] >= 0) & (q[:, 0] < w) & (q[:, 1] >= 0) & (q[:, 1] < h)
    out = np.zeros(len(X), dtype=bool)
    qi = q[inside]
    out[np.nonzero(inside)[0]] = ev.valid[qi[:, 1], qi[:, 0]] & \
        (ev.support_coarse[qi[:, 1], qi[:, 0]] > MIN_SUPPORT)
    return out


def _tube(path: FloatArray, radius_mm: float, step_mm: float
          ) -> tuple[FloatArray, NDArray[np.int64]]:
    """The voxels (N, 3) of a grid of ``step_mm`` (with their indices (N, 3)) within
    ``radius_mm`` of the polyline ``path`` (P, 3): a cube of offsets around points of the
    path, merged, then cut to the distance."""
    along = _densify(path, radius_mm / 2.0)
    k = int(np.ceil(radius_mm / step_mm)) + 1
    r = np.arange(-k, k + 1)
    cube = np.stack(np.meshgrid(r, r, r, indexing="ij"), axis=-1).reshape(-1, 3)
    cube = cube[np.linalg.norm(cube, axis=1) * step_mm <= radius_mm + radius_mm / 2.0]
    centre = np.rint(along / step_mm).astype(np.int64)
    every = (centre[:, None, :] + cube[None, :, :]).reshape(-1, 3)
    lo = every.min(axis=0)
    dims = every.max(axis=0) - lo + 1
    key = np.unique(np.ravel_multi_index(tuple((every - lo).T), tuple(dims)))
    ijk = np.column_stack(np.unravel_index(key, tuple(dims))) + lo
    X = ijk * step_mm
    dist, _ = cKDTree(_densify(path, step_mm)).query(X, distance_upper_bound=radius_mm)
    keep = np.isfinite(dist)
    return X[keep], ijk[keep]


def _densify(X: FloatArray, step_mm: float) -> FloatArray:
    """Points along the polyline X (N, 3) at most ``step_mm`` apart."""
    out = [X[:1]]
    for a, b in zip(X[:-1], X[1:], strict=True):
        n = max(int(np.ceil(np.linalg.norm(b - a) / step_mm)), 1)
        out.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.vstack(out)


def _along_epipolar(p_b: FloatArray, epipole_b: FloatArray, s_mm: FloatArray
                    ) -> NDArray[np.bool_]:
    """(M,) bool: stretches of at least ALONG_MIN_MM whose image in B runs along B's
    epipolar lines."""
    t = np.gradient(p_b, axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-9)
    e = p_b - epipole_b
    e /= np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-9)
    along = np.abs(np.sum(t * e, axis=1)) > ALONG_COS
    out = np.zeros_like(along)
    m = np.concatenate([[False], along, [False]]).astype(np.int8)
    starts, stops = np.nonzero(np.diff(m) == 1)[0], np.nonzero(np.diff(m) == -1)[0]
    for a, b in zip(starts, stops, strict=True):
        if s_mm[b - 1] - s_mm[a] >= ALONG_MIN_MM:
            out[a:b] = True
    return out


def _no_support(clicks_a: FloatArray, clicks_b: FloatArray, view_a: ViewGeometry,
                view_b: ViewGeometry, ev_a: ViewEvidence, ev_b: ViewEvidence, X0: FloatArray,
                X1: FloatArray) -> TraceError:
    """The refusal when no path has vessel support in both views: names the view whose
    support along the chord between the ends is the weaker, and the place."""
    t = np.linspace(0.0, 1.0, 64)[:, None]
    X = X0 + t * (X1 - X0)
    worst = []
    for name, view, ev in (("A", view_a, ev_a), ("B", view_b, ev_b)):
        s = _sample(ev.support_coarse, view.project(X))
        worst.append((float(np.mean(s)), name, view.project(X)[int(np.argmin(s))]))
    _, name, place = min(worst)
    return TraceError(
        f"view {name}: no vessel joins the end clicks in both views; add a waypoint on the "
        f"vessel in view {name} near ({place[0]:.0f}, {place[1]:.0f})",
        view=name, near_px=place)
