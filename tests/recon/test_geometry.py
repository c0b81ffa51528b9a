import numpy as np
import pytest

from recon.geometry import (
    ViewGeometry,
    epipolar_lines,
    fundamental_matrix,
    point_line_distance_px,
    ray_distance_mm,
    relative_pose,
    rotation_from_rotvec,
    rotvec_from_rotation,
    triangulate,
    view_separation_deg,
)

# The seed paper's Table 1 (LAO/RAO, CRA/CAU, SID, SOD) for its three data sets.
TABLE1 = {
    "data1": ((45.5, -28.2, 1200, 749), (-24.8, -27.0, 1147, 844)),
    "data2": ((45.2, 0.0, 1028, 759.4), (0.9, 33.0, 1064, 766.4)),
    "data3": ((-21.6, -21.0, 1075, 782.7), (44.3, -28.8, 1118, 785)),
}


def make_view(alpha, beta, sid=1000.0, sod=750.0, **kw):
    return ViewGeometry(alpha, beta, sid, sod, (0.3, 0.3), 512, 512, **kw)


def heart_points(n=200, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-50, 50, size=(n, 3))


def test_ap_view_orientation():
    ap = make_view(0.0, 0.0)
    assert np.allclose(ap.nominal_axes[2], [0, -1, 0])  # detector above the chest
    centre = np.array(ap.centre_px)
    left, head = ap.project([[10.0, 0, 0], [0, 0, 10.0]])
    assert left[0] > centre[0] + 1  # patient's left on the right of the image
    assert head[1] < centre[1] - 1  # head at the top
    assert np.allclose(ap.project([[0.0, 0, 0]])[0], centre)


def test_projection_matrix_matches_direct_projection():
    view = make_view(30.0, 20.0, rotvec_corr=(0.01, -0.02, 0.005), t_corr_mm=(2.0, -1.0, 3.0))
    X = heart_points()
    xh = np.column_stack([X, np.ones(len(X))]) @ view.P.T
    assert np.allclose(xh[:, :2] / xh[:, 2:], view.project(X), atol=1e-9)


def test_detector_and_source_positions():
    view = make_view(-29.3, 25.5, sid=976, sod=720)
    assert np.isclose(np.linalg.norm(view.source_world), 720)
    assert np.isclose(np.linalg.norm(view.detector_centre_world - view.source_world), 976)
    assert np.allclose(view.project(view.detector_centre_world[None]), [view.centre_px])


@pytest.mark.parametrize("name", sorted(TABLE1))
@pytest.mark.parametrize("method", ["paper", "dlt"])
def test_triangulation_round_trip_table1(name, method):
    (a1, b1, sid1, sod1), (a2, b2, sid2, sod2) = TABLE1[name]
    va = make_view(a1, b1, sid1, sod1)
    vb = make_view(a2, b2, sid2, sod2, rotvec_corr=(0.02, 0.01, -0.015), t_corr_mm=(3, -2, 5))
    X = heart_points()
    Xr = triangulate(va.project(X), vb.project(X), va, vb, method=method)
    assert np.max(np.linalg.norm(Xr - X, axis=1)) < 1e-9


@pytest.mark.parametrize("name", sorted(TABLE1))
def test_epipolar_constraint_holds(name):
    (a1, b1, sid1, sod1), (a2, b2, sid2, sod2) = TABLE1[name]
    va = make_view(a1, b1, sid1, sod1)
    vb = make_view(a2, b2, sid2, sod2, t_corr_mm=(1.0, 2.0, -3.0))
    X = heart_points()
    pa, pb = va.project(X), vb.project(X)
    F = fundamental_matrix(va, vb)
    ha = np.column_stack([pa, np.ones(len(pa))])
    hb = np.column_stack([pb, np.ones(len(pb))])
    assert np.max(np.abs(np.einsum("ni,ij,nj->n", hb, F, ha))) < 1e-9
    lines = epipolar_lines(pa, va, vb)
    assert np.max(np.abs(np.sum(lines * hb, axis=1))) < 1e-7  # px
    # Consistent with F built the textbook way, [e_b]_x P_b P_a^+.
    C_a = np.append(va.source_world, 1.0)
    e_b = vb.P @ C_a
    ex = np.array([[0, -e_b[2], e_b[1]], [e_b[2], 0, -e_b[0]], [-e_b[1], e_b[0], 0]])
    F2 = ex @ vb.P @ np.linalg.pinv(va.P)
    F2 /= np.linalg.norm(F2)
    assert min(np.linalg.norm(F - F2), np.linalg.norm(F + F2)) < 1e-9


def test_point_line_distance_is_euclidean():
    lines = np.array([[0.0, 1.0, -5.0]])  # row = 5
    d = point_line_distance_px(lines, [[3.0, 9.0], [100.0, 5.0]])
    assert np.allclose(d, [[4.0, 0.0]])


def test_relative_pose_eq1():
    va = make_view(-30, 25)
    vb = make_view(30, 24, sid=1100, sod=800)
    R, t = relative_pose(va, vb)
    X = heart_points(20)
    x_a, x_b = va.to_view_frame(X), vb.to_view_frame(X)
    assert np.allclose((x_a - t) @ R.T, x_b, atol=1e-9)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)


def test_correction_moves_rig_rigidly_and_composes():
    v = make_view(10, 5)
    rv, t = np.array([0.01, 0.02, -0.03]), np.array([1.0, 2.0, 3.0])
    vc = v.with_correction(rv, t)
    R = rotation_from_rotvec(rv)
    assert np.allclose(vc.source_world, R @ v.source_world + t)
    X = heart_points(10)
    # Moving the rig is the same as moving the world the opposite way.
    assert np.allclose(vc.project(X @ R.T + t), v.project(X), atol=1e-9)
    assert np.allclose(rotvec_from_rotation(rotation_from_rotvec(rv)), rv)
    undone = vc.with_correction([0, 0, 0], -t).with_correction(-rv, [0, 0, 0])
    assert np.allclose(undone.R_corr, np.eye(3), atol=1e-12)
    assert np.allclose(undone.t_corr_mm, 0.0, atol=1e-12)


def test_ray_distance_zero_for_true_pairs_and_positive_otherwise():
    va, vb = make_view(-30, 25), make_view(30, 24)
    X = heart_points(30)
    pa, pb = va.project(X), vb.project(X)
    assert np.max(ray_distance_mm(pa, pb, va, vb)) < 1e-9
    assert np.min(ray_distance_mm(pa, pb + [0.0, 5.0], va, vb)) > 0.1


def test_view_separation():
    assert np.isclose(view_separation_deg(make_view(-30, 0), make_view(30, 0)), 60.0)


def test_invalid_geometry_rejected():
    with pytest.raises(ValueError, match="sod_mm"):
        make_view(0, 0, sid=700, sod=750)


def test_pixel_size_at_the_isocenter_is_the_detector_spacing_over_the_magnification():
    view = ViewGeometry(0.0, 0.0, 1000.0, 750.0, (0.4, 0.2), 512, 512)
    assert view.pixel_mm_at_isocenter == pytest.approx(0.3 * 750.0 / 1000.0)
