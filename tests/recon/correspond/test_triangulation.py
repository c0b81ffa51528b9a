import numpy as np
import pytest
from test_matching import coronary_curve, projected_centerline, table1_views

from recon.correspond.matching import match_centerlines
from recon.correspond.triangulation import (
    TriangulationError,
    build_centerline_3d,
    point_polyline_distance,
    radius_mm_eq11,
    table3_metrics,
)
from recon.types import Centerline2D, Matching


def curve_length(X):
    return float(np.linalg.norm(np.diff(X, axis=0), axis=1).sum())


def perfect_reconstruction(name="data1", kind="tortuous", smoothing_mm=0.1):
    """Noise-free data, lightly smoothed: the reconstruction must be exact."""
    X = coronary_curve(kind)
    va, vb = table1_views(name)
    ca, cb = projected_centerline(X, va), projected_centerline(X, vb)
    m = match_centerlines(ca, cb, va, vb, method="match3")
    return X, va, vb, m, build_centerline_3d(m, va, vb, smoothing_mm=smoothing_mm)


def test_default_smoothing_keeps_shape_and_removes_noise_length():
    X, va, vb, m, _ = perfect_reconstruction("data1", kind="gentle")
    clean = build_centerline_3d(m, va, vb)  # default smoothing on perfect data: small bias
    assert np.sqrt(np.mean(point_polyline_distance(clean.X_world, X) ** 2)) < 0.1
    assert abs(clean.length_mm - curve_length(X)) < 0.003 * curve_length(X)
    rng = np.random.default_rng(1)
    noisy = Matching(
        method=m.method,
        points_a_px=m.points_a_px + rng.normal(0, 0.5, m.points_a_px.shape),
        points_b_px=m.points_b_px + rng.normal(0, 0.5, m.points_b_px.shape),
        index_a=m.index_a,
        index_b=m.index_b,
        centerline_a=m.centerline_a,
        centerline_b=m.centerline_b,
        standard_view=m.standard_view,
    )
    light = build_centerline_3d(noisy, va, vb, smoothing_mm=0.2)
    default = build_centerline_3d(noisy, va, vb)
    true_length = curve_length(X)
    # Depth noise inflates the length of a lightly smoothed curve; the default does not.
    assert light.length_mm - true_length > abs(default.length_mm - true_length)
    assert abs(default.length_mm - true_length) < 0.005 * true_length


def test_point_polyline_distance():
    poly = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    pts = np.array([[5.0, 3.0], [12.0, 5.0], [-3.0, -4.0], [10.0, 10.0]])
    assert np.allclose(point_polyline_distance(pts, poly), [3.0, 2.0, 5.0, 0.0])
    assert np.allclose(point_polyline_distance(pts, poly, chunk=1), [3.0, 2.0, 5.0, 0.0])


@pytest.mark.parametrize("name", ["data1", "data2", "data3"])
def test_perfect_data_reconstructs_the_curve(name):
    X, va, vb, m, cl = perfect_reconstruction(name)
    assert np.sqrt(np.mean(point_polyline_distance(cl.X_world, X) ** 2)) < 0.05
    assert abs(cl.length_mm - curve_length(X)) < 0.005 * curve_length(X)
    assert np.allclose(np.diff(cl.s_mm), cl.s_mm[1] - cl.s_mm[0])
    assert abs(cl.s_mm[1] - 0.25) < 0.01
    assert np.allclose(np.linalg.norm(cl.tangents, axis=1), 1.0)
    chords = np.diff(cl.X_world, axis=0)
    chords /= np.linalg.norm(chords, axis=1, keepdims=True)
    assert np.median(np.einsum("nd,nd->n", chords, cl.tangents[:-1])) > 0.999
    assert cl.X_raw_world.shape == (len(m.points_a_px), 3)
    assert np.array_equal(cl.points_a_px, m.points_a_px)
    # ends stay at the truth's ends (proximal first)
    assert np.linalg.norm(cl.X_world[0] - X[0]) < 0.3
    assert np.linalg.norm(cl.X_world[-1] - X[-1]) < 0.3


def test_table3_is_zero_for_perfect_data():
    _, va, vb, m, cl = perfect_reconstruction("data2")
    t3 = table3_metrics(cl, m, va, vb)
    for view in ("a", "b"):
        assert t3[view]["rms_px"] < 0.05 and t3[view]["max_px"] < 0.2
        assert np.isclose(t3[view]["mean_mm"], t3[view]["mean_px"] * 0.3)
        assert t3[view]["n"] == len(m.centerline_a.points_px)
    assert t3["ray_distance_mean_mm"] < 0.01
    assert t3["backprojection_rms_mm"] < 0.015


def test_table3_sees_a_miscalibration():
    _, va, vb, m, cl = perfect_reconstruction("data2")
    vb_bad = vb.with_correction([0.0, 0.0, 0.0], [0.0, 0.0, 2.0])
    t3 = table3_metrics(cl, m, va, vb_bad)
    assert t3["b"]["mean_mm"] > 1.0
    assert t3["ray_distance_mean_mm"] > 1.0


def test_eq11_cylinder_radius_at_known_depth():
    _, vb = table1_views("data1")
    va = table1_views("data3")[0]
    R = vb.R_view_from_world  # rows u, v, d of view B
    # a straight cylinder of radius 1.5 mm, 40 mm nearer the source than the isocenter
    centre = -40.0 * R[2]
    axis = (R[0] + 0.3 * R[1]) / np.linalg.norm(R[0] + 0.3 * R[1])
    X = centre + np.linspace(-20, 20, 400)[:, None] * axis
    radius_mm = 1.5

    def traced(view):
        # the projected half-width, measured from the two silhouette points
        ray = X - view.source_world
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        side = np.cross(ray, axis)
        side /= np.linalg.norm(side, axis=1, keepdims=True)
        half = np.linalg.norm(
            view.project(X + radius_mm * side) - view.project(X - radius_mm * side), axis=1
        ) / 2.0
        return Centerline2D(points_px=view.project(X), radius_px=half, brightness=np.ones(400))

    ca, cb = traced(va), traced(vb)
    m = match_centerlines(ca, cb, va, vb, method="match3")
    cl = build_centerline_3d(m, va, vb)
    assert np.allclose(cl.radius_a_mm, radius_mm, rtol=0.01)
    assert np.allclose(cl.radius_b_mm, radius_mm, rtol=0.01)
    assert np.allclose(cl.radius_mm, radius_mm, rtol=0.01)
    # and the isocenter magnification would be wrong by several percent here
    naive = cb.radius_px[200] * 0.3 * vb.sod_mm / vb.sid_mm
    assert abs(naive - radius_mm) > 0.04 * radius_mm


def test_radius_eq11_formula():
    _, vb = table1_views("data2")
    X = np.array([[0.0, 0.0, 0.0], [10.0, -20.0, 5.0]])
    r = radius_mm_eq11([10.0, 10.0], X, vb)
    assert np.isclose(r[0], 10.0 * 0.3 * vb.sod_mm / vb.sid_mm)  # isocenter: SOD / SID
    d = vb.depth_mm(X[1:])[0]
    assert np.isclose(r[1], 10.0 * 0.3 * d / vb.sid_mm)  # same ratio along any ray


def test_too_few_pairs():
    cl = Centerline2D(np.zeros((3, 2)) + [[0, 0], [1, 0], [2, 0]], np.ones(3), np.ones(3))
    m = Matching("match1", cl.points_px, cl.points_px, np.arange(3), np.arange(3), cl, cl, "a")
    va, vb = table1_views("data1")
    with pytest.raises(TriangulationError):
        build_centerline_3d(m, va, vb)


def _with_overlap(
    cl: Centerline2D, X: np.ndarray, view, start: float, stop: float, factor: float
) -> Centerline2D:
    """The trace with its radius widened by ``factor`` and its reliability 0.1 where it
    shows the stretch [start, stop] (fractions of 3D arc length) of the curve X (another
    vessel lying over it there)."""
    s3 = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(X, axis=0), axis=1))])
    p = view.project(X)
    nearest = np.argmin(np.linalg.norm(cl.points_px[:, None] - p[None], axis=2), axis=1)
    frac = s3[nearest] / s3[-1]
    sel = (frac >= start) & (frac <= stop)
    radius, reliability = cl.radius_px.copy(), np.ones(len(frac))
    radius[sel] *= factor
    reliability[sel] = 0.1
    return Centerline2D(cl.points_px, radius, cl.brightness, reliability=reliability)


def test_overlap_in_one_view_takes_the_other_views_radius():
    X = coronary_curve("gentle")
    va, vb = table1_views("data1")
    ca = _with_overlap(projected_centerline(X, va), X, va, 0.4, 0.6, 1.8)
    cb = projected_centerline(X, vb)
    m = match_centerlines(ca, cb, va, vb, method="match3")
    fixed = build_centerline_3d(m, va, vb)
    raw = build_centerline_3d(m, va, vb, overlap_substitution=False)
    assert not np.any(fixed.overlap_b) and not np.any(raw.overlap_a)
    mid = fixed.s_mm / fixed.length_mm
    inside = (mid > 0.45) & (mid < 0.55)
    outside = (mid < 0.3) | (mid > 0.7)
    assert np.all(fixed.overlap_a[inside]) and not np.any(fixed.overlap_a[outside])
    # As traced, A's radius is 1.8x B's on the overlap; substituted, they agree.
    assert np.median(raw.radius_a_mm[inside] / raw.radius_b_mm[inside]) > 1.6
    assert np.allclose(fixed.radius_a_mm[inside], fixed.radius_b_mm[inside])
    assert np.allclose(fixed.radius_a_mm[outside], raw.radius_a_mm[outside])


@pytest.mark.parametrize(("factor", "substituted"), [(0.3, True), (0.8, False)])
def test_an_untrusted_view_that_collapsed_takes_the_other_views_radius(factor, substituted):
    """A fit beside a touching neighbour can collapse instead of widening (a side branch
    running along its parent): where the untrusted view reads much narrower (below 0.6
    of the other view) the other view's radius stands in; a mildly narrower untrusted
    view (a lesion it may see better) is kept."""
    X = coronary_curve("gentle")
    va, vb = table1_views("data1")
    ca = _with_overlap(projected_centerline(X, va), X, va, 0.4, 0.6, factor)
    cb = projected_centerline(X, vb)
    m = match_centerlines(ca, cb, va, vb, method="match3")
    fixed = build_centerline_3d(m, va, vb)
    raw = build_centerline_3d(m, va, vb, overlap_substitution=False)
    mid = fixed.s_mm / fixed.length_mm
    inside = (mid > 0.45) & (mid < 0.55)
    ratio = np.median(raw.radius_a_mm[inside] / raw.radius_b_mm[inside])
    assert ratio < 0.4 if substituted else 0.65 < ratio < 1.0  # as traced
    assert np.all(fixed.overlap_a[inside]) == substituted
    if substituted:
        assert np.allclose(fixed.radius_a_mm[inside], fixed.radius_b_mm[inside])
        # each view's own fit is kept for the intervals
        np.testing.assert_allclose(fixed.fit_radius_a_mm, raw.radius_a_mm)
        np.testing.assert_allclose(fixed.fit_radius_b_mm, raw.radius_b_mm)
    else:
        assert np.allclose(fixed.radius_a_mm, raw.radius_a_mm)
        assert fixed.fit_radius_a_mm is None and fixed.fit_radius_b_mm is None


def test_overlap_in_both_views_keeps_both_radii():
    X = coronary_curve("gentle")
    va, vb = table1_views("data1")
    ca = _with_overlap(projected_centerline(X, va), X, va, 0.4, 0.6, 1.5)
    cb = _with_overlap(projected_centerline(X, vb), X, vb, 0.4, 0.6, 1.5)
    c3 = build_centerline_3d(match_centerlines(ca, cb, va, vb, method="match3"), va, vb)
    mid = c3.s_mm / c3.length_mm
    inside = (mid > 0.45) & (mid < 0.55)
    assert not np.any(c3.overlap_a[inside]) and not np.any(c3.overlap_b[inside])


def test_point_polyline_distance_in_the_image_plane_is_that_in_space() -> None:
    """The 2D path (per coordinate) gives the distances of the general one: a random
    polyline and points laid in the z = 0 plane of 3D, and hand-checked distances."""
    rng = np.random.default_rng(5)
    line = np.cumsum(rng.normal(size=(300, 2)) * 4.0, axis=0)
    pts = rng.uniform(-60.0, 60.0, size=(700, 2)) + line.mean(axis=0)
    flat = point_polyline_distance(pts, line, chunk=64)
    lifted = point_polyline_distance(np.c_[pts, np.zeros(len(pts))],
                                     np.c_[line, np.zeros(len(line))], chunk=64)
    np.testing.assert_allclose(flat, lifted, rtol=1e-12, atol=1e-12)
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    np.testing.assert_allclose(point_polyline_distance(
        np.array([[5.0, -3.0], [13.0, 5.0], [14.0, 13.0], [5.0, 4.0]]), square),
        [3.0, 3.0, 5.0, 4.0])
