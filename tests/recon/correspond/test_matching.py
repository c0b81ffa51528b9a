import itertools

import numpy as np
import pytest

from recon.correspond.matching import (
    MATCHERS,
    NARROWING_WEIGHT_PX,
    MatchingError,
    cost_matrix,
    deviation_pairs,
    dp_match,
    match_centerlines,
    narrowing_profile,
)
from recon.correspond.triangulation import build_centerline_3d, point_polyline_distance
from recon.geometry import ViewGeometry, epipolar_lines
from recon.types import Centerline2D, arclength

# Synthetic scene shared with test_triangulation.py (no images).
# The seed paper's Table 1 (LAO/RAO, CRA/CAU, SID, SOD) for its three data sets.
TABLE1 = {
    "data1": ((45.5, -28.2, 1200, 749), (-24.8, -27.0, 1147, 844)),
    "data2": ((45.2, 0.0, 1028, 759.4), (0.9, 33.0, 1064, 766.4)),
    "data3": ((-21.6, -21.0, 1075, 782.7), (44.3, -28.8, 1118, 785)),
}


def table1_views(name: str) -> tuple[ViewGeometry, ViewGeometry]:
    (a1, b1, sid1, sod1), (a2, b2, sid2, sod2) = TABLE1[name]
    va = ViewGeometry(a1, b1, sid1, sod1, (0.3, 0.3), 512, 512)
    vb = ViewGeometry(a2, b2, sid2, sod2, (0.3, 0.3), 512, 512)
    return va, vb


def coronary_curve(kind: str = "tortuous", n: int = 3000) -> np.ndarray:
    """A space curve (n, 3) in mm on a ~38 mm sphere around the heart centre."""
    t = np.linspace(0.0, 1.0, n)
    if kind == "tortuous":
        phi = -0.9 + 2.2 * t
        theta = 1.2 + 0.5 * np.sin(2.5 * np.pi * t)
        r = 35 + 4 * np.sin(5 * np.pi * t)
    else:  # "gentle"
        phi = -0.8 + 1.8 * t
        theta = 1.3 + 0.25 * np.sin(2 * np.pi * t)
        r = np.full_like(t, 38.0)
    st = np.sin(theta)
    return np.stack([r * st * np.cos(phi), r * st * np.sin(phi), r * np.cos(theta) - 10], 1)


def projected_centerline(
    X_world: np.ndarray,
    view: ViewGeometry,
    *,
    spacing_px: float = 1.0,
    radius_px: float = 4.0,
    noise_px: float = 0.0,
    seed: int = 0,
) -> Centerline2D:
    """Project a curve and resample it at uniform 2D spacing.

    Brightness dips (darker, more contrast) where the curve is foreshortened
    in this view (more vessel length per pixel), as on a real angiogram.
    """
    p = view.project(X_world)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    n = int(s[-1] / spacing_px) + 1
    s_new = np.linspace(0.0, s[-1], n)
    pts = np.column_stack([np.interp(s_new, s, p[:, 0]), np.interp(s_new, s, p[:, 1])])
    s3 = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(X_world, axis=0), axis=1))])
    ds3 = np.gradient(np.interp(s_new, s, s3))
    foreshortening = ds3 / np.median(ds3)
    brightness = 100.0 - 20.0 * np.clip(foreshortening - 1.0, 0.0, None)
    if noise_px:
        pts = pts + np.random.default_rng(seed).normal(0.0, noise_px, pts.shape)
    return Centerline2D(points_px=pts, radius_px=np.full(n, radius_px), brightness=brightness)



# ------------------------------------------------------------------- DP
def path_cost(cost, j):
    return cost[np.arange(len(j)), j].sum()


def brute_force(cost, steps_s, steps_c):
    """Best valid path by enumeration (tiny matrices only)."""
    ns, nc = cost.shape
    best, best_j = np.inf, None
    for diffs in itertools.product(*[range(int(s) + 1) for s in steps_s[:-1]]):
        j = np.concatenate([[0], np.cumsum(diffs)])
        if j[-1] != nc - 1:
            continue
        run = 1
        ok = True
        for i in range(1, ns):
            run = run + 1 if j[i] == j[i - 1] else 1
            if run > steps_c[j[i]]:
                ok = False
                break
        if ok and path_cost(cost, j) < best:
            best, best_j = path_cost(cost, j), j
    return best, best_j


def test_dp_follows_cheap_diagonal():
    cost = np.ones((6, 6)) - np.eye(6)
    assert np.array_equal(dp_match(cost, np.full(6, 2), np.full(6, 2)), np.arange(6))


def test_dp_known_path_with_repeat_and_jump():
    path = [0, 0, 1, 3, 4]
    cost = np.ones((5, 5))
    cost[np.arange(5), path] = 0.0
    assert np.array_equal(dp_match(cost, np.full(5, 2), np.full(5, 2)), path)


def test_dp_step_size_limits_jumps():
    # the cheap path jumps by 3 between rows 1 and 2
    path = [0, 0, 3, 4, 5, 5]
    cost = np.ones((6, 6))
    cost[np.arange(6), path] = 0.0
    j3 = dp_match(cost, np.array([2, 3, 2, 2, 2, 2]), np.full(6, 2))
    assert np.array_equal(j3, path)  # CBOCD_1 = 3 allows m = 3
    j2 = dp_match(cost, np.full(6, 2), np.full(6, 2))
    assert np.abs(np.diff(j2)).max() <= 2 and path_cost(cost, j2) > 0


def test_dp_exceptional_case_limits_repeats():
    # cheapest: stay on column 0 for four rows, then go to the end
    cost = np.ones((6, 4))
    cost[:4, 0] = 0.0
    cost[4, 2] = 0.0
    cost[5, 3] = 0.0
    free = dp_match(cost, np.full(6, 2), np.array([4, 2, 2, 2]))
    assert np.array_equal(free, [0, 0, 0, 0, 2, 3])
    limited = dp_match(cost, np.full(6, 2), np.array([2, 2, 2, 2]))
    runs = np.diff(np.flatnonzero(np.diff(np.r_[-1, limited, 99])))
    assert runs.max() <= 2  # j repeated at most CBOCD_j - 1 = 1 time
    assert np.count_nonzero(limited == 0) == 2


def test_dp_both_ends_pinned():
    cost = np.ones((5, 5))
    cost[0, 3] = cost[-1, 0] = -10.0  # tempting but not at the pinned ends
    j = dp_match(cost, np.full(5, 2), np.full(5, 2))
    assert j[0] == 0 and j[-1] == 4
    assert np.all(np.diff(j) >= 0)


@pytest.mark.parametrize("seed", range(6))
def test_dp_is_optimal_against_brute_force(seed):
    rng = np.random.default_rng(seed)
    ns, nc = 6, int(rng.integers(4, 8))
    cost = rng.random((ns, nc))
    steps_s = rng.integers(2, 4, ns)
    steps_c = rng.integers(1, 4, nc)
    best, _ = brute_force(cost, steps_s, steps_c)
    if not np.isfinite(best):
        with pytest.raises(MatchingError):
            dp_match(cost, steps_s, steps_c)
        return
    j = dp_match(cost, steps_s, steps_c)
    assert j[0] == 0 and j[-1] == nc - 1
    assert np.all(np.diff(j) >= 0) and np.all(np.diff(j) <= steps_s[:-1])
    assert np.isclose(path_cost(cost, j), best)


def test_dp_unreachable_raises():
    with pytest.raises(MatchingError):
        dp_match(np.zeros((3, 10)), np.full(3, 2), np.full(10, 2))


def test_dp_rejects_bad_shapes():
    with pytest.raises(ValueError):
        dp_match(np.zeros((3, 3)), np.full(4, 2), np.full(3, 2))


# ----------------------------------------------------------- COST, deviation
def test_cost_matrix_is_epipolar_distance():
    va, vb = table1_views("data1")
    X = coronary_curve("gentle", 40)
    pa, pb = va.project(X), vb.project(X)
    cost = cost_matrix(pa, pb, va, vb)
    assert cost.shape == (40, 40)
    assert np.allclose(np.diag(cost), 0.0, atol=1e-6)  # true pairs lie on their lines
    line = epipolar_lines(pa[7:8], va, vb)[0]
    expected = np.abs(pb @ line[:2] + line[2]) / np.hypot(line[0], line[1])
    assert np.allclose(cost[7], expected)


def test_deviation_pairs():
    cost = np.array([[0.1, 3.0, 4.0], [5.0, 4.0, 3.5], [2.0, 0.2, 9.0]])
    ps = np.arange(6.0).reshape(3, 2)
    pc = 10 + np.arange(6.0).reshape(3, 2)
    dev = deviation_pairs(cost, ps, pc, threshold_px=2.0)
    assert dev.max_row_min_px == 3.5
    assert list(dev.index_standard) == [1] and list(dev.index_constructed) == [2]
    assert np.array_equal(dev.points_standard_px, ps[[1]])
    assert np.array_equal(dev.points_constructed_px, pc[[2]])
    none = deviation_pairs(cost, ps, pc, threshold_px=5.0)
    assert len(none.index_standard) == 0 and none.points_standard_px.shape == (0, 2)


# ----------------------------------------------------------- full matching
def reconstruct_rms(kind, name, method, **kw):
    X = coronary_curve(kind)
    va, vb = table1_views(name)
    ca, cb = projected_centerline(X, va), projected_centerline(X, vb)
    m = match_centerlines(ca, cb, va, vb, method=method, **kw)
    cl3d = build_centerline_3d(m, va, vb)
    err = point_polyline_distance(cl3d.X_world, X)
    return float(np.sqrt(np.mean(err**2))), m


@pytest.mark.parametrize("name", sorted(TABLE1))
def test_match3_recovers_curve(name):
    rms, m = reconstruct_rms("tortuous", name, "match3")
    assert rms < 0.1
    assert m.method == "match3" and m.standard_view in ("a", "b")
    assert np.all(np.diff(m.index_a) >= 0) and np.all(np.diff(m.index_b) >= 0)


def test_match2_recovers_curve_without_strong_relative_foreshortening():
    rms, _ = reconstruct_rms("gentle", "data2", "match2")
    assert rms < 0.1


@pytest.mark.parametrize("name", sorted(TABLE1))
def test_match1_clearly_worse_and_match3_best(name):
    rms = {m: reconstruct_rms("tortuous", name, m)[0] for m in MATCHERS}
    assert rms["match1"] > 5 * rms["match3"]
    assert rms["match3"] <= rms["match2"]
    assert rms["match4"] > 5 * rms["match3"]  # several crossings of the epipolar line


def test_standard_is_the_longer_trace_and_ab_order_is_kept():
    X = coronary_curve("gentle")
    va, vb = table1_views("data1")
    ca, cb = projected_centerline(X, va), projected_centerline(X, vb)
    assert ca.length_px > cb.length_px
    m_ab = match_centerlines(ca, cb, va, vb)
    m_ba = match_centerlines(cb, ca, vb, va)
    assert m_ab.standard_view == "a" and m_ba.standard_view == "b"
    assert np.allclose(m_ab.points_a_px, m_ba.points_b_px)
    assert np.allclose(m_ab.points_b_px, m_ba.points_a_px)
    assert np.allclose(m_ab.centerline_a.points_px[m_ab.index_a], m_ab.points_a_px)
    assert len(m_ab.centerline_a.points_px) == len(m_ab.centerline_b.points_px)


def test_epipolar_miss_gives_deviation_pairs():
    X = coronary_curve("gentle")
    va, vb = table1_views("data3")
    ca = projected_centerline(X, va)
    cb = projected_centerline(X[200:], vb)  # view B's trace starts later: lines miss it
    m = match_centerlines(ca, cb, va, vb, threshold_px=2.0)
    assert m.max_row_min_cost_px > 2.0
    assert len(m.deviation_a_px) > 0 and m.deviation_a_px.shape == m.deviation_b_px.shape
    m_ok = match_centerlines(ca, projected_centerline(X, vb), va, vb)
    assert m_ok.max_row_min_cost_px < 1.0 and len(m_ok.deviation_a_px) == 0


def test_huge_traces_are_capped():
    X = coronary_curve("gentle")
    va, vb = table1_views("data2")
    ca = projected_centerline(X, va, spacing_px=0.2)
    cb = projected_centerline(X, vb, spacing_px=0.2)
    m = match_centerlines(ca, cb, va, vb, max_points=600)
    assert len(m.centerline_a.points_px) == 600 == len(m.index_a)


def test_unknown_method():
    X = coronary_curve("gentle", 100)
    va, vb = table1_views("data2")
    ca, cb = projected_centerline(X, va), projected_centerline(X, vb)
    with pytest.raises(ValueError, match="match9"):
        match_centerlines(ca, cb, va, vb, method="match9")


# ------------------------------------------------ OPE: a distal end seen end-on
def end_on_curve(view: ViewGeometry, tilt_rad: float = 0.2) -> np.ndarray:
    """The gentle curve, then 12 mm turning towards ``view``'s source (tilted by tilt_rad).

    In that view the last ~12 mm project onto a few pixels (and are dark): an
    OPE that needs many standard points per constructed point.
    """
    X = coronary_curve("gentle", 2000)
    to_src = view.source_world - X[-1]
    to_src /= np.linalg.norm(to_src)
    t = X[-1] - X[-2]
    t /= np.linalg.norm(t)
    perp = t - (t @ to_src) * to_src
    perp /= np.linalg.norm(perp)
    d = np.cos(tilt_rad) * to_src + np.sin(tilt_rad) * perp
    s = np.linspace(0.0, 12.0, 400)[1:]
    w = np.clip(s / 3.0, 0.0, 1.0)[:, None]  # turn over the first 3 mm
    dirs = (1 - w) * t + w * d
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    return np.vstack([X, X[-1] + np.cumsum(dirs * (s[1] - s[0]), axis=0)])


@pytest.mark.parametrize("name", ["data1", "data3"])
def test_match3_follows_an_end_on_ope_where_match2_gets_stuck(name):
    va, vb = table1_views(name)
    X = end_on_curve(vb)
    ca = projected_centerline(X, va, spacing_px=0.5)
    cb = projected_centerline(X, vb, spacing_px=0.5)
    rms = {}
    for method in ("match2", "match3"):
        m = match_centerlines(ca, cb, va, vb, method=method)
        err = point_polyline_distance(build_centerline_3d(m, va, vb).X_world, X)
        rms[method] = float(np.sqrt(np.mean(err**2)))
        if method == "match3":  # B (constructed) repeats its end points more than twice
            runs = np.bincount(m.index_b)
            assert m.standard_view == "a" and runs.max() > 2
    assert rms["match3"] < 0.1
    assert rms["match2"] > 3 * rms["match3"]


# ------------------------------------------------------------ narrowing term
def test_narrowing_profile_sees_a_dip_not_a_widening_or_a_taper():
    x = np.arange(400.0)
    ref = 5.0 - 0.004 * x  # tapering vessel, px
    dip = 0.5 * (1 + np.cos(2 * np.pi * np.clip((x - 150) / 40, -0.5, 0.5))) / 2
    bump = 0.6 * np.exp(-0.5 * ((x - 300) / 6) ** 2)  # an overlap widens one view
    n = narrowing_profile(ref * (1 - dip) * (1 + bump))
    assert n[150] == pytest.approx(0.5, abs=0.02)
    assert np.max(n[np.abs(x - 150) > 25]) < 0.02


def _with_dip(cl: Centerline2D, X: np.ndarray, view: ViewGeometry, s0_mm: float) -> Centerline2D:
    """The trace with a 50 % raised-cosine narrowing, 6 mm long, at 3D arc length s0_mm."""
    s_3d = arclength(X)
    s_at = np.interp(arclength(cl.points_px), arclength(view.project(X)), s_3d)
    u = np.clip((s_at - s0_mm) / 6.0, -0.5, 0.5)
    radius = cl.radius_px * (1 - 0.5 * (1 + np.cos(2 * np.pi * u)) / 2)
    return Centerline2D(points_px=cl.points_px, radius_px=radius, brightness=cl.brightness)


def test_narrowing_term_keeps_the_lesion_aligned_under_a_calibration_error():
    """B rotated by 0.8 deg: the epipolar COST alone slides the correspondence along
    the vessel by ~1.75 mm at the lesion, so the two views' narrowings land at
    different places of the 3D centerline (and the MLD is overestimated)."""
    X = coronary_curve("gentle")
    va, vb = table1_views("data1")
    vb_wrong = vb.with_correction(np.array([0.0, 0.0, np.deg2rad(0.8)]), np.zeros(3))
    s0 = 0.5 * arclength(X)[-1]
    ca = _with_dip(projected_centerline(X, va), X, va, s0)
    cb = _with_dip(projected_centerline(X, vb), X, vb, s0)

    def gap_mm(weight: float) -> float:
        m = match_centerlines(ca, cb, va, vb_wrong, method="match3", narrowing_weight_px=weight)
        c = build_centerline_3d(m, va, vb_wrong)
        return abs(c.s_mm[np.argmin(c.radius_a_mm)] - c.s_mm[np.argmin(c.radius_b_mm)])

    assert gap_mm(0.0) > 1.0
    assert gap_mm(NARROWING_WEIGHT_PX) <= 0.3
