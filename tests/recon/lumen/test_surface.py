import numpy as np
import pytest
from support import centerline_3d, straight

from recon.geometry import ViewGeometry
from recon.lumen.surface import (
    CrossSections,
    SurfaceResult,
    build_surface,
    elliptic_cross_sections,
    intersection_directions,
)
from recon.types import Centerline3D

VIEW_A = ViewGeometry(-30.0, 0.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)
VIEW_B = ViewGeometry(30.0, 0.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)
# AP and lateral: for a vessel along z the two intersection lines are x and y.
VIEW_AP = ViewGeometry(0.0, 0.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)
VIEW_LAT = ViewGeometry(90.0, 0.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)


def helix(radius=12.0, pitch=15.0, turns=0.8, step=0.25):
    arc = turns * np.hypot(2 * np.pi * radius, pitch)
    th = np.linspace(0.0, 2 * np.pi * turns, int(arc / step) + 1)
    X = np.column_stack([radius * np.cos(th), radius * np.sin(th), pitch * th / (2 * np.pi)])
    return X, arc


def dist_to_polyline(P, X):
    """Distance (N,) of points P (N, 3) to the polyline X (M, 3) and the closest points."""
    a, seg = X[:-1], np.diff(X, axis=0)
    tau = np.einsum("nmk,mk->nm", P[:, None] - a[None], seg) / np.sum(seg**2, axis=1)
    tau = np.clip(tau, 0.0, 1.0)
    closest = a[None] + tau[..., None] * seg[None]
    d = np.linalg.norm(P[:, None] - closest, axis=2)
    j = np.argmin(d, axis=1)
    return d[np.arange(len(P)), j], closest[np.arange(len(P)), j]


def assert_clean_closed_mesh(mesh):
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.volume > 0
    assert np.all(mesh.area_faces > 0)
    assert len(mesh.split(only_watertight=False)) == 1


# --------------------------------------------------------------- sections
def test_straight_tube_has_circular_sections_of_the_given_radius():
    cl = centerline_3d(straight(), 1.5)
    sec = elliptic_cross_sections(cl, VIEW_A, VIEW_B)
    assert isinstance(sec, CrossSections) and len(sec) == len(cl.X_world)
    np.testing.assert_allclose(sec.major_mm, 1.5)
    np.testing.assert_allclose(sec.minor_mm, 1.5)
    np.testing.assert_allclose(sec.area_mm2, np.pi * 1.5**2)
    np.testing.assert_allclose(sec.centers, cl.X_world)
    for axis in (sec.major_axis, sec.minor_axis):
        np.testing.assert_allclose(np.linalg.norm(axis, axis=1), 1.0)
        np.testing.assert_allclose(np.einsum("ij,ij->i", axis, sec.normals), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", sec.major_axis, sec.minor_axis), 0, atol=1e-12)


@pytest.mark.parametrize("r_a, r_b", [(2.0, 1.0), (1.0, 2.0)])
def test_perpendicular_lines_give_major_and_minor_axes(r_a, r_b):
    X = straight(direction=(0.0, 0.0, 1.0), origin=(0.0, 0.0, 0.0))
    sec = elliptic_cross_sections(centerline_3d(X, r_a, r_b), VIEW_AP, VIEW_LAT)
    np.testing.assert_allclose(sec.major_mm, 2.0)
    np.testing.assert_allclose(sec.minor_mm, 1.0, atol=1e-6)
    # View AP looks along y, so its diameter lies along x; the lateral view's along y.
    expected_major = np.array([1.0, 0.0, 0.0]) if r_a > r_b else np.array([0.0, 1.0, 0.0])
    np.testing.assert_allclose(np.abs(sec.major_axis @ expected_major), 1.0, atol=1e-3)
    # Axis signs are kept consistent along the vessel.
    assert np.all(np.einsum("ij,ij->i", sec.major_axis[1:], sec.major_axis[:-1]) > 0)


def test_endpoint_of_the_shorter_line_lies_on_the_ellipse():
    X = straight(direction=(0.0, 0.0, 1.0), origin=(0.0, 0.0, 0.0))
    cl = centerline_3d(X, 2.0, 1.5)  # lines 60 degrees apart (views at -30 / +30)
    sec = elliptic_cross_sections(cl, VIEW_A, VIEW_B)
    l_b = intersection_directions(cl.X_world, sec.normals, VIEW_B)
    p = 1.5 * l_b
    x = np.einsum("ij,ij->i", p, sec.major_axis)
    y = np.einsum("ij,ij->i", p, sec.minor_axis)
    np.testing.assert_allclose((x / sec.major_mm) ** 2 + (y / sec.minor_mm) ** 2, 1.0, atol=1e-9)
    assert np.all(sec.minor_mm < 1.5) and np.all(sec.minor_mm > 1.4)


def test_intersection_line_is_perpendicular_to_tangent_and_ray():
    X, _ = helix()
    cl = centerline_3d(X, 1.0)
    lines = intersection_directions(cl.X_world, cl.tangents, VIEW_A)
    rays = cl.X_world - VIEW_A.source_world
    np.testing.assert_allclose(np.einsum("ij,ij->i", lines, cl.tangents), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.einsum("ij,ij->i", lines, rays), 0.0, atol=1e-7)
    # Its projection is the image normal of the projected centerline (up to perspective).
    p0 = VIEW_A.project(cl.X_world)
    t2 = VIEW_A.project(cl.X_world + 0.1 * cl.tangents) - p0
    l2 = VIEW_A.project(cl.X_world + 0.1 * lines) - p0
    cos = np.abs(np.einsum("ij,ij->i", t2, l2)) / (
        np.linalg.norm(t2, axis=1) * np.linalg.norm(l2, axis=1)
    )
    assert cos.max() < 0.02


def test_parallel_lines_fall_back_to_the_shorter_half_length():
    cl = centerline_3d(straight(), 2.0, 1.2)
    sec = elliptic_cross_sections(cl, VIEW_A, VIEW_A)
    np.testing.assert_allclose(sec.major_mm, 2.0)
    np.testing.assert_allclose(sec.minor_mm, 1.2)


def test_vessel_along_the_ray_still_gives_valid_sections():
    d = VIEW_AP.R_view_from_world[2]  # central ray of the AP view
    cl = centerline_3d(straight(direction=d, origin=(0.0, 0.0, 0.0)), 1.0, 1.0)
    sec = elliptic_cross_sections(cl, VIEW_AP, VIEW_LAT)
    assert np.all(np.isfinite(sec.major_axis)) and np.all(np.isfinite(sec.minor_mm))
    np.testing.assert_allclose(sec.minor_mm, 1.0)


def test_bad_centerline_raises_value_error():
    cl = centerline_3d(straight(), 1.0)
    bad = Centerline3D(
        X_world=cl.X_world,
        s_mm=cl.s_mm,
        tangents=cl.tangents,
        radius_a_mm=cl.radius_a_mm[:-1],
        radius_b_mm=cl.radius_b_mm,
        X_raw_world=cl.X_raw_world,
        points_a_px=cl.points_a_px,
        points_b_px=cl.points_b_px,
    )
    with pytest.raises(ValueError):
        elliptic_cross_sections(bad, VIEW_A, VIEW_B)
    with pytest.raises(ValueError):
        build_surface(cl, VIEW_A, VIEW_B, voxel_mm=-1.0)


# ------------------------------------------------------------------ mesh
def test_straight_tube_mesh_volume_and_outward_normals():
    r, length = 1.5, 40.0
    cl = centerline_3d(straight(length=length), r)
    res = build_surface(cl, VIEW_A, VIEW_B)
    assert isinstance(res, SurfaceResult)
    mesh = res.mesh
    assert_clean_closed_mesh(mesh)
    expected = np.pi * r**2 * length + 4.0 / 3.0 * np.pi * r**3  # tube + two hemispheres
    assert mesh.volume == pytest.approx(expected, rel=0.02)
    dist, closest = dist_to_polyline(mesh.vertices, cl.X_world)
    np.testing.assert_allclose(dist, r, atol=0.5 * res.voxel_mm)
    outward = np.einsum("ij,ij->i", mesh.vertex_normals, mesh.vertices - closest)
    assert np.all(outward > 0)
    # The caps reach one radius beyond each end.
    axis = cl.tangents[0]
    along = (mesh.vertices - cl.X_world[0]) @ axis
    assert along.min() == pytest.approx(-r, abs=res.voxel_mm)
    assert along.max() == pytest.approx(length + r, abs=res.voxel_mm)


def test_point_cloud_lies_on_the_ellipses_and_caps():
    cl = centerline_3d(straight(length=10.0), 1.5)
    res = build_surface(cl, VIEW_A, VIEW_B, n_angles=16)
    n_rings = 4
    assert res.point_cloud.shape == (len(cl.X_world) * 16 + 2 * (n_rings * 16 + 1), 3)
    dist, _ = dist_to_polyline(res.point_cloud, cl.X_world)
    np.testing.assert_allclose(dist, 1.5, atol=1e-9)


def test_helix_tube_mesh():
    r = 1.2
    X, arc = helix()
    res = build_surface(centerline_3d(X, r), VIEW_A, VIEW_B, voxel_mm=0.2)
    assert_clean_closed_mesh(res.mesh)
    expected = np.pi * r**2 * arc + 4.0 / 3.0 * np.pi * r**3
    assert res.mesh.volume == pytest.approx(expected, rel=0.02)
    dist, _ = dist_to_polyline(res.mesh.vertices, X)
    np.testing.assert_allclose(dist, r, atol=0.1)


def test_elliptic_tube_mesh_volume():
    X = straight(length=30.0, direction=(0.0, 0.0, 1.0), origin=(0.0, 0.0, 0.0))
    res = build_surface(centerline_3d(X, 2.0, 1.0), VIEW_AP, VIEW_LAT, voxel_mm=0.15)
    assert_clean_closed_mesh(res.mesh)
    a, b = 2.0, 1.0
    expected = np.pi * a * b * 30.0 + 4.0 / 3.0 * np.pi * a * b * np.sqrt(a * b)
    assert res.mesh.volume == pytest.approx(expected, rel=0.02)
    # Wider along x (the AP view's diameter) than along y.
    mid = np.abs(res.mesh.vertices[:, 2]) < 10.0
    extent = np.ptp(res.mesh.vertices[mid], axis=0)
    assert extent[0] == pytest.approx(2 * a, abs=0.1)
    assert extent[1] == pytest.approx(2 * b, abs=0.1)


def test_tapering_stenosed_tube_is_closed():
    X = straight(length=60.0)
    s = np.linspace(0.0, 60.0, len(X))
    r = (2.0 - s / 60.0) * (
        1 - 0.6 * np.where(np.abs(s - 30) < 5, 0.5 * (1 + np.cos(2 * np.pi * (s - 30) / 10)), 0.0)
    )
    res = build_surface(centerline_3d(X, r, 0.9 * r), VIEW_A, VIEW_B)
    assert_clean_closed_mesh(res.mesh)



# ------------------------------------------------------------------ the tree
def test_tree_surface_is_the_union_of_a_y_with_no_internal_faces():
    from recon.lumen.surface import build_tree_surface

    main = centerline_3d(straight(length=40.0, direction=(1, 0, 0), origin=(0, 0, 0)), 1.5)
    t = np.deg2rad(50.0)
    side_X = np.arange(0.0, 20.0 + 1e-9, 0.25)[:, None] * np.array([np.cos(t), np.sin(t), 0.0])
    side = centerline_3d(side_X, 1.0)  # starts on the main vessel's axis
    sections = [elliptic_cross_sections(c, VIEW_A, VIEW_B) for c in (main, side)]
    res = build_tree_surface(sections, voxel_mm=0.2)
    assert res.components == 1
    assert_clean_closed_mesh(res.mesh)
    v_main = np.pi * 1.5**2 * 40.0 + 4.0 / 3.0 * np.pi * 1.5**3
    v_side = np.pi * 1.0**2 * 20.0 + 4.0 / 3.0 * np.pi * 1.0**3
    # the union: more than the main vessel alone, less than the two counted apart
    assert v_main + 0.8 * v_side < res.mesh.volume < v_main + v_side
    # no face inside either vessel: every vertex is on the wall of one and not deep in the other
    d_main, _ = dist_to_polyline(res.mesh.vertices, main.X_world)
    d_side, _ = dist_to_polyline(res.mesh.vertices, side.X_world)
    on_main = np.abs(d_main - 1.5) < 0.2
    on_side = np.abs(d_side - 1.0) < 0.2
    assert np.all(on_main | on_side)
    assert not np.any(d_main < 1.5 - 0.3)  # nothing deep inside the main lumen
    assert not np.any(d_side[d_main > 1.5] < 1.0 - 0.3)


def test_tree_surface_of_two_apart_vessels_has_two_components():
    from recon.lumen.surface import build_tree_surface

    a = centerline_3d(straight(length=20.0, direction=(1, 0, 0), origin=(0, 0, 0)), 1.0)
    b = centerline_3d(straight(length=20.0, direction=(1, 0, 0), origin=(0, 8, 0)), 1.0)
    sections = [elliptic_cross_sections(c, VIEW_A, VIEW_B) for c in (a, b)]
    assert build_tree_surface(sections, voxel_mm=0.25).components == 2


def test_pieces_tells_a_second_vessel_from_a_cavity_inside_the_first():
    import trimesh

    from recon.lumen.mesh_repair import pieces as _pieces

    outer = trimesh.creation.icosphere(radius=3.0)
    pocket = trimesh.creation.icosphere(radius=0.5)
    pocket.invert()  # wound like an outside pocket within the inside
    apart = trimesh.creation.icosphere(radius=1.0)
    apart.apply_translation([10.0, 0.0, 0.0])
    assert _pieces(trimesh.util.concatenate([outer, pocket])) == (1, 1, 0)
    assert _pieces(trimesh.util.concatenate([outer, apart])) == (2, 0, 0)
    # a closed surface under one voxel (0.2 mm) beside the union is a speck, either sign;
    # the 1 mm sphere apart (4.2 mm3) stays a piece
    speck = trimesh.creation.icosphere(radius=0.05)
    speck.apply_translation([5.0, 0.0, 0.0])
    hollow = speck.copy()
    hollow.apply_translation([0.0, 5.0, 0.0])
    hollow.invert()
    assert _pieces(trimesh.util.concatenate([outer, apart, speck, hollow]),
                   speck_mm3=0.2**3) == (2, 0, 2)


@pytest.mark.parametrize("direction", [(1, 0, 0), (1, 1, 1), (2, 1, 0)])
def test_a_lumen_pinched_below_the_grid_stays_one_piece(direction):
    """A 99 % narrowing (0.02 mm radius at its neck) is thinner than the grid can
    sample: the mesh draws the neck at least one voxel wide rather than cutting the
    vessel in two (the sections, and so the measurements, keep the true neck)."""
    from recon.lumen.surface import build_tree_surface

    X = straight(length=20.0, direction=direction, origin=(0, 0, 0))
    s = np.linspace(0.0, 20.0, len(X))
    r = 1.2 - 1.18 * np.where(np.abs(s - 10) < 2, 0.5 * (1 + np.cos(np.pi * (s - 10) / 2)), 0.0)
    sections = elliptic_cross_sections(centerline_3d(X, r), VIEW_A, VIEW_B)
    assert sections.minor_mm.min() <= 0.05
    res = build_surface(centerline_3d(X, r), VIEW_A, VIEW_B, voxel_mm=0.2)
    assert_clean_closed_mesh(res.mesh)
    assert res.sections.minor_mm.min() <= 0.05  # measured as it is
    side = centerline_3d(straight(length=10.0, direction=(0, 0, 1), origin=tuple(X[10])), 0.8)
    tree = build_tree_surface([sections, elliptic_cross_sections(side, VIEW_A, VIEW_B)],
                              voxel_mm=0.2)
    assert tree.components == 1
    assert_clean_closed_mesh(tree.mesh)
