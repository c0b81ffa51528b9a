"""Tests of recon.trace.trace_path: the orientation-aware route and the checks of a trace."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from scipy import ndimage as ndi
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree
from test_intensity import path_length, xray

from recon.trace.centerline import TraceError, trace_segment
from recon.trace.trace_path import (
    N_HEADINGS,
    _edge_slots,
    _Graph,
    find_route_problem,
    ring_circuits,
    route_distance,
)


def segment(p, q, n=3000):
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.asarray(p, float) * (1 - t) + np.asarray(q, float) * t


def test_a_faint_stenosis_is_followed_not_bypassed_along_a_stronger_parallel_vessel() -> None:
    """A low-contrast vessel narrows by 60 %; a strong parallel vessel 18 px away is
    joined to it by two branches around the lesion, a detour that a cost on the
    image-normalised response took."""
    shape = (120, 240)
    main = segment((10, 60), (230, 60))
    r_main = 3.0 - 1.8 * np.exp(-0.5 * ((main[:, 0] - 120.0) / 4.0) ** 2)
    # path length of the narrowing tube, by pixel: nearest centre point's radius
    rr, cc = np.mgrid[0 : shape[0], 0 : shape[1]]
    sub = (np.arange(4) + 0.5) / 4 - 0.5
    tree = cKDTree(main)
    length_main = np.zeros(shape)
    for dy in sub:
        for dx in sub:
            d, i = tree.query(np.column_stack([(cc + dx).ravel(), (rr + dy).ravel()]))
            chord = 2.0 * np.sqrt(np.clip(r_main[i] ** 2 - d**2, 0.0, None))
            length_main += chord.reshape(shape) / 16.0
    others = (path_length(shape, segment((10, 78), (230, 78)), 3.0)
              + path_length(shape, segment((70, 60), (85, 78)), 2.5)
              + path_length(shape, segment((155, 78), (170, 60)), 2.5))
    img = 1000.0 * np.exp(-0.03 * length_main - 0.12 * others)
    img = ndi.gaussian_filter(img, 0.7) + np.random.default_rng(1).normal(0.0, 3.0, shape)
    cl = trace_segment(img, [(20.0, 60.0), (220.0, 60.0)])
    assert cKDTree(main).query(cl.points_px)[0].max() < 0.5
    at_lesion = np.abs(cl.points_px[:, 0] - 120.0) < 1.0
    assert cl.radius_px[at_lesion].min() < 0.6 * np.median(cl.radius_px)


def test_clicks_out_of_order_are_refused_at_the_waypoint() -> None:
    line = segment((10, 40), (190, 40))
    img = xray(path_length((80, 200), line, 3.0), "lin", mu=0.06)
    with pytest.raises(TraceError, match=r"^view B: the trace doubles back at click 2 "
                                         r"\(150, 40\)") as info:
        trace_segment(img, [(20.0, 40.0), (150.0, 40.0), (80.0, 40.0)], view="B")
    err = info.value
    assert "\n" not in str(err) and err.view == "B"
    np.testing.assert_allclose(err.near_px, (150.0, 40.0), atol=1.0)
    again = pickle.loads(pickle.dumps(err))  # attributes survive a worker process
    assert str(again) == str(err) and again.view == "B"
    np.testing.assert_allclose(again.near_px, err.near_px)


def test_a_gap_in_the_vessel_is_refused_where_it_is() -> None:
    a, b = segment((10, 40), (93, 40)), segment((107, 40), (190, 40))
    img = xray(path_length((80, 200), a, 2.0) + path_length((80, 200), b, 2.0), "lin", mu=0.08)
    with pytest.raises(TraceError, match=r"^view A: the trace between click 1 and click 2 "
                                         r"leaves the vessel near \(\d+, \d+\); add a "
                                         r"waypoint on the vessel there$") as info:
        trace_segment(img, [(20.0, 40.0), (180.0, 40.0)])
    assert abs(info.value.near_px[0] - 100.0) < 6.0 and abs(info.value.near_px[1] - 40.0) < 3.0


def test_route_problems_on_drawn_curves() -> None:
    s = np.arange(0.0, 200.0, 0.5)
    straight = np.column_stack([s, np.zeros_like(s)])
    r = np.full(len(s), 2.0)
    ok = np.ones(len(s), bool)
    assert find_route_problem(straight, r, ok) is None
    off = ok.copy()
    off[100:130] = False  # 15 px off the vessel
    problem = find_route_problem(straight, r, off)
    assert problem is not None and problem.kind == "leaves the vessel"
    assert 100 <= problem.index < 130
    off = ok.copy()
    off[100:105] = False  # 2.5 px: a crossing's centre, not a problem
    assert find_route_problem(straight, r, off) is None
    # a hairpin: out 80 px, a half turn of radius 2 px, back 80 px
    a = np.arange(0.0, np.pi, 0.5 / 2.0)
    leg = np.arange(0.0, 80.0, 0.5)
    hair = np.vstack([np.column_stack([leg, np.zeros_like(leg)]),
                      np.column_stack([80.0 + 2.0 * np.sin(a), 2.0 - 2.0 * np.cos(a)]),
                      np.column_stack([leg[::-1], np.full_like(leg, 4.0)])])
    problem = find_route_problem(hair, np.full(len(hair), 2.0), np.ones(len(hair), bool))
    assert problem is not None and problem.kind == "doubles back"
    assert abs(hair[problem.index, 0] - 80.0) < 10.0
    # a loop that crosses itself once (transversally) is fine
    t = np.linspace(-2.7, 2.7, 1200)
    loop = np.column_stack([20 * t - 45 * np.sin(t), 45 * np.cos(t)])
    loop = loop[np.concatenate([[True], np.linalg.norm(np.diff(loop, axis=0), axis=1) > 0])]
    assert find_route_problem(loop, np.full(len(loop), 2.0), np.ones(len(loop), bool)) is None


def test_a_loop_is_followed_round_not_cut_at_its_crossing() -> None:
    t = np.linspace(-2.9, 2.9, 6000)
    loop = np.column_stack([150 + 20 * t - 45 * np.sin(t), 80 + 45 * np.cos(t)])
    img = xray(path_length((170, 300), loop, 2.0, ss=3), "lin", mu=0.1)
    k0, k1 = np.argmin(np.abs(t + 2.75)), np.argmin(np.abs(t - 2.75))
    true_length = np.sum(np.linalg.norm(np.diff(loop[k0:k1], axis=0), axis=1))
    cl = trace_segment(img, [loop[k0], loop[k1]])
    assert cl.length_px > 0.95 * true_length


def test_a_tight_loop_is_followed_round_through_the_hole_of_its_ring() -> None:
    """A ring about two lumens across (its hole a lumen wide) below a crossing: the band
    at the clicked vessel's level fills the ring in, so only the hole at a higher
    response level shows the loop (recon.trace.trace_path.hole_apices). Cut across, the
    trace misses the ring by about 20 px."""
    t = np.linspace(-np.pi - 1.2, np.pi + 1.2, 3000)
    ring = np.column_stack([150 + 4.0 * t - 11.0 * np.sin(t), 80 + 11.0 * np.cos(t)])
    lead_in = segment(ring[0] - (80, 0), ring[0], 400)
    lead_out = segment(ring[-1], ring[-1] + (80, 0), 400)
    path = np.vstack([lead_in, ring, lead_out])
    img = xray(path_length((170, 320), path, 3.0, ss=3), "lin", mu=0.1)
    cl = trace_segment(img, [path[100], path[-100]])
    gap, _ = cKDTree(cl.points_px).query(path[110:-110])
    assert gap.max() < 2.0


def test_ring_circuits_goes_round_a_ring_below_a_crossing() -> None:
    """A band of a straight vessel with a ring hanging below it (hole 10 px across): one
    circuit, round the ring's centre line, from and back to its point nearest the
    route, heading the way the route heads there."""
    rr, cc = np.mgrid[0:80, 0:200].astype(float)
    band = np.abs(rr - 20) <= 3  # the vessel, route along row 20 heading +col
    ring_d = np.hypot(rr - 33.0, cc - 60.0)
    band |= np.abs(ring_d - 8.0) <= 3.0  # ring: centre line 8 px round (60, 33)
    route = np.column_stack([np.arange(5.0, 195.0), np.full(190, 20.0)])
    found = ring_circuits(band, route, 3.5)
    assert len(found) == 1
    index, circuit = found[0]
    assert abs(route[index, 0] - 60.0) < 4.0  # at the crossing
    assert np.allclose(circuit[0], circuit[-1])
    radius = np.hypot(circuit[:, 0] - 60.0, circuit[:, 1] - 33.0)
    assert np.all(np.abs(radius - 8.0) < 1.5)  # the ring's centre line
    assert circuit[1, 0] - circuit[0, 0] > 0  # heading +col, as the route does


@pytest.mark.parametrize("move_px", [2, 3, 4])
def test_the_graph_is_built_in_csr_order_as_from_its_edge_list(move_px: int) -> None:
    """The (pixel, heading) graph assembled straight in CSR order equals the matrix that
    scipy makes from its edge list (edges (p, k - dk) -> (q, k), dk in -1, 0, 1): the
    same rows, column order and weights (Dijkstra's ties depend on the order)."""
    rng = np.random.default_rng(3)
    rr, cc = np.mgrid[0:40, 0:50].astype(float)
    band = (np.abs(np.hypot(rr - 20, cc - 25) - 12) <= 3) | (np.abs(rr - 8) <= 2)
    band &= rng.random(band.shape) > 0.05  # holes and loose pixels
    resp, scale = rng.random(band.shape), rng.uniform(1.0, 3.0, band.shape)
    direction, junction = rng.uniform(-np.pi, np.pi, band.shape), rng.random(band.shape)
    graph = _Graph(band, resp, np.log(scale), direction, move_px, junction)
    cost = ((1.05) / (0.05 + resp)) ** 2
    across = 2.0 * resp * cost / 2.0
    terms = (cost + across, -across * np.cos(2 * direction), -across * np.sin(2 * direction))
    r0, r1, c0, c1 = graph.box  # the maps _moves reads are on the band's box
    terms = tuple(t[r0:r1, c0:c1] for t in terms)
    turn = 0.3 * (1.0 + 30.0 * junction[graph.rows, graph.cols])
    src, dst, wt = [], [], []
    for length_px in (move_px,) if move_px <= 3 else (move_px, move_px - 1):
        q, ok, move = graph._moves(length_px, terms, np.log(scale))
        pi, ki = np.nonzero(ok)
        for dk in (-1, 0, 1):
            src.append(pi * N_HEADINGS + (ki - dk) % N_HEADINGS)
            dst.append(q[pi, ki] * N_HEADINGS + ki)
            wt.append(move[pi, ki] + turn[pi] * abs(dk))
    m = len(graph.rows) * N_HEADINGS
    ref = csr_matrix((np.concatenate(wt), (np.concatenate(src), np.concatenate(dst))),
                     shape=(m, m))
    assert graph.graph.nnz == ref.nnz > 0
    for field in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(graph.graph, field), getattr(ref, field))


@pytest.mark.parametrize("lengths", [(2,), (3,), (4, 3)])
def test_edge_slots_give_each_node_its_own_slots(lengths: tuple[int, ...]) -> None:
    slots = _edge_slots(lengths)
    n_cand = 3 * len(lengths)
    assert slots.shape == (n_cand, N_HEADINGS)
    for j in range(N_HEADINGS):
        assert sorted(slots[:, j]) == list(range(j * n_cand, (j + 1) * n_cand))


def test_route_distance_is_the_distance_to_the_nearest_route_pixel() -> None:
    t = np.linspace(0.0, 1.0, 200)
    route = np.column_stack([-5.0 + 50.0 * t, 10.0 + 12.0 * np.sin(6.0 * t)])  # leaves the grid
    dist = route_distance((30, 40), route)
    pixels = np.unique(np.rint(route[:, ::-1]).astype(int), axis=0)
    pixels = pixels[(pixels[:, 0] >= 0) & (pixels[:, 0] < 30) & (pixels[:, 1] >= 0)
                    & (pixels[:, 1] < 40)]
    rr, cc = np.mgrid[0:30, 0:40]
    brute = np.min(np.hypot(rr[..., None] - pixels[:, 0], cc[..., None] - pixels[:, 1]), axis=2)
    assert np.array_equal(dist, brute)


def test_a_search_bounded_by_cost_gives_the_unbounded_route(monkeypatch) -> None:
    """The route's searches are bounded at a few multiples of the straight distance,
    raised until the cheapest arrival lies inside the bound: the route (a curved vessel
    with a waypoint and a parallel neighbour) is the unbounded search's, whether the
    first bound suffices or every bound is too small."""
    import recon.trace.trace_path as tp
    from recon.trace.centerline import compute_vesselness, snap_click

    shape = (140, 220)
    t = np.linspace(0.0, 1.0, 3000)
    bend = np.column_stack([20 + 180 * t, 70 + 40 * np.sin(np.pi * t)])
    other = segment((20, 40), (200, 40))
    img = xray(path_length(shape, bend, 3.0) + path_length(shape, other, 2.5), "lin",
               mu=0.06)
    vmap = compute_vesselness(img)
    clicks = np.array([snap_click(vmap, c)[0] for c in ([25.0, 72.0], [110.0, 110.0],
                                                         [195.0, 72.0])])
    routes = {}
    for name, per_px, steps in (("unbounded", 2.0, ()), ("as set", tp._LIMIT_PER_PX,
                                                          tp._LIMIT_STEPS),
                                ("every bound too small", 1e-3, (1.0, 2.0))):
        monkeypatch.setattr(tp, "_LIMIT_PER_PX", per_px)
        monkeypatch.setattr(tp, "_LIMIT_STEPS", steps)
        routes[name] = tp.minimal_route(vmap, clicks)
    for name in ("as set", "every bound too small"):
        np.testing.assert_array_equal(routes[name].path_px, routes["unbounded"].path_px)
        np.testing.assert_array_equal(routes[name].click_index,
                                      routes["unbounded"].click_index)
    # on the bent vessel (the pixel route, within its 3 px lumen), not the neighbour
    assert cKDTree(bend).query(routes["unbounded"].path_px)[0].max() < 4.0



def test_a_branch_traced_from_its_bifurcation_click_goes_straight_into_the_branch() -> None:
    """A phantom tree (the tree suite's random pair 5; view B) whose side branch leaves
    its parent at a sharp angle in projection, its first click on the parent's edge:
    no move leaves that pixel towards the branch, and from the click alone the route
    ran up the parent, wheeled round in a wide blob 80 px away and came back (refused as
    doubling back). The first leg may start within one move of the click."""
    from recon.synth.suites import random_geometry
    from recon.synth.tree_case import make_tree_case

    pair = random_geometry(np.random.default_rng([0, 5, 15]), "random-5")
    tc = make_tree_case(pair, 5, "both", stenosis_pct=57.2)
    case, branch = tc.case, tc.seeds.segments[1]
    view = case.view_b_true
    cl = trace_segment(case.image_b, np.asarray(branch.b_px, float), view="B",
                       pixel_mm=view.pixel_mm_at_isocenter)
    truth_px = view.project(case.truth.vessels[tc.vessels[1]][0])
    off, nearest = cKDTree(truth_px).query(cl.points_px)
    assert np.median(off) < 1.0 and off.max() < 4.0  # on the branch from start to end
    true_length = np.sum(np.linalg.norm(np.diff(truth_px[nearest[0]:nearest[-1] + 1], axis=0),
                                        axis=1))
    length = np.sum(np.linalg.norm(np.diff(cl.points_px, axis=0), axis=1))
    assert length < 1.1 * true_length  # no detour
