import json

import numpy as np
import pytest
from scipy.integrate import simpson

from recon import phantom as ph
from recon.geometry import ViewGeometry, rotvec_from_rotation
from recon.seeds import load_seeds


@pytest.fixture(scope="module")
def rendered():
    return ph.make_phantom("data1", 3, stenosis_pct=50.0)


def small_ap_view(size=101, spacing=0.3):
    # Odd size: pixel (50, 50) is the principal point, its ray is the central ray.
    return ViewGeometry(0.0, 0.0, 1000.0, 750.0, (spacing, spacing), size, size)


def straight(p0, p1, radius0, radius1=None, step=0.1):
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    n = int(round(np.linalg.norm(p1 - p0) / step)) + 1
    t = np.linspace(0.0, 1.0, n)
    r1 = radius0 if radius1 is None else radius1
    return p0 + t[:, None] * (p1 - p0), radius0 + t * (r1 - radius0)


def chord_x_cylinder(view, pixels, radius):
    """Exact chord (N,) of pixel rays through the infinite cylinder y^2 + z^2 = r^2."""
    w = view.ray_directions(pixels)
    S = view.source_world
    a = w[:, 1] ** 2 + w[:, 2] ** 2
    b = S[1] * w[:, 1] + S[2] * w[:, 2]
    c = S[1] ** 2 + S[2] ** 2 - radius**2
    disc = np.maximum(b**2 - a * c, 0.0)
    return 2.0 * np.sqrt(disc) / a


# ------------------------------------------------------------ presets, header
def test_presets_match_table1_and_the_real_pair():
    a, b = ph.PRESETS["data2"].view_a, ph.PRESETS["data2"].view_b
    assert (a.alpha_deg, a.beta_deg, a.sid_mm, a.sod_mm) == (45.2, 0.0, 1028.0, 759.4)
    assert (b.alpha_deg, b.beta_deg, b.sid_mm, b.sod_mm) == (0.9, 33.0, 1064.0, 766.4)
    s = ph.PRESETS["static"]
    assert (s.view_a.alpha_deg, s.view_a.beta_deg, s.view_b.alpha_deg) == (-29.3, 25.5, 30.7)
    for preset in ph.PRESETS.values():
        for view in (preset.view_a, preset.view_b):
            assert (view.rows, view.cols) == (512, 512)
            assert view.pixel_spacing_mm == (0.390625, 0.390625)


def test_random_header_error_magnitudes():
    rng = np.random.default_rng(0)
    view = ph.PRESETS["data1"].view_b
    angles, shifts = [], []
    for _ in range(200):
        rotvec, t_mm = ph.random_header_error(rng, view)
        angles.append(np.degrees(np.linalg.norm(rotvec)))
        shifts.append(np.linalg.norm(t_mm))
    # Two orthogonal rotations (about z and about u) of 1..2 degrees each.
    assert np.sqrt(2.0) - 0.01 < min(angles) and max(angles) < 2 * np.sqrt(2.0) + 0.01
    assert 3.0 < np.median(shifts) < 15.0


def test_header_error_is_the_documented_correction():
    case = ph.make_phantom("data3", 5, render=False)
    t = case.truth
    again = case.view_b_nominal.with_correction(t.correction_rotvec, t.correction_t_mm)
    assert np.allclose(again.P, case.view_b_true.P)
    assert case.view_b_nominal == ph.PRESETS["data3"].view_b
    assert case.view_a == ph.PRESETS["data3"].view_a
    off = ph.make_phantom("data3", 5, render=False, header_error=False)
    assert off.view_b_true == off.view_b_nominal
    # The correction carries the nominal rig onto the true one.
    R = case.view_b_true.R_view_from_world.T @ case.view_b_nominal.R_view_from_world
    angle = np.linalg.norm(rotvec_from_rotation(R.T))
    assert np.isclose(angle, np.linalg.norm(t.correction_rotvec))


# ------------------------------------------------------------ geometry / truth
def test_same_seed_same_case_and_other_seed_differs():
    a = ph.make_phantom("data2", 11, render=False)
    b = ph.make_phantom("data2", 11, render=False)
    c = ph.make_phantom("data2", 12, render=False)
    assert a.seeds == b.seeds
    assert np.array_equal(a.truth.segment_X_world, b.truth.segment_X_world)
    assert np.array_equal(a.truth.correction_t_mm, b.truth.correction_t_mm)
    assert not np.array_equal(a.truth.correction_t_mm, c.truth.correction_t_mm)
    assert a.image_a is None and a.image_b is None


def test_stenosis_percentage_does_not_change_the_tree():
    a = ph.make_phantom("static", 4, stenosis_pct=30.0, render=False)
    b = ph.make_phantom("static", 4, stenosis_pct=70.0, render=False)
    assert a.seeds == b.seeds
    assert np.array_equal(a.truth.segment_X_world, b.truth.segment_X_world)
    assert a.truth.mld_mm > b.truth.mld_mm


@pytest.mark.parametrize("preset", sorted(ph.PRESETS))
def test_tree_is_heart_sized_and_inside_the_field(preset):
    for seed in range(4):
        case = ph.make_phantom(preset, seed, render=False)
        t = case.truth
        main_X, main_r = t.vessels[0]
        main_len = np.sum(np.linalg.norm(np.diff(main_X, axis=0), axis=1))
        assert 79.0 < main_len < 141.0
        assert 2 <= len(t.vessels) <= 4
        assert main_r[0] > 1.7 and main_r[-1] < 1.2
        X = np.vstack([v[0] for v in t.vessels])
        assert np.abs(X).max() <= ph.TREE_EXTENT_MM
        for view in (case.view_a, case.view_b_true):
            p = view.project(X)
            assert p.min() >= 20.0 and p.max() <= 490.0
        # Samples every 0.1 mm along the segment.
        steps = np.linalg.norm(np.diff(t.segment_X_world, axis=0), axis=1)
        assert np.allclose(steps, 0.1, atol=2e-3)
        assert 0.0 < t.stenosis_s_mm < t.segment_length_mm


def test_branches_leave_at_30_to_70_degrees():
    for seed in range(5):
        t = ph.make_phantom("data1", seed, render=False).truth
        main_X = t.vessels[0][0]
        for Xb, _ in t.vessels[1:]:
            i = np.argmin(np.linalg.norm(main_X - Xb[0], axis=1))
            tm = main_X[min(i + 5, len(main_X) - 1)] - main_X[max(i - 5, 0)]
            tb = Xb[10] - Xb[0]
            cos = tm @ tb / np.linalg.norm(tm) / np.linalg.norm(tb)
            assert 28.0 < np.degrees(np.arccos(cos)) < 72.0


def test_seeds_agree_with_the_projected_truth():
    for seed in range(5):
        case = ph.make_phantom("data1", seed, render=False)
        t = case.truth
        seg = case.seeds.segments[0]
        assert seg.name == "main"
        for view, clicks in ((case.view_a, seg.a), (case.view_b_true, seg.b)):
            truth_px = t.segment_px(view)
            assert np.linalg.norm(clicks[0] - truth_px[0]) < 3.0
            assert np.linalg.norm(clicks[-1] - truth_px[-1]) < 3.0
            assert 3 <= len(clicks) <= 4  # ends plus 1-2 waypoints
            # Waypoints lie on the projected segment.
            d = np.linalg.norm(clicks[1:-1, None, :] - truth_px[None], axis=2).min(axis=1)
            assert np.all(d < 3.0)
        pa, pb, names = case.seeds.correspondences()
        assert names == list(t.feature_names)
        assert np.all(np.linalg.norm(pa - case.view_a.project(t.features_world), axis=1) < 3.0)
        assert np.all(np.linalg.norm(pb - case.view_b_true.project(t.features_world), axis=1) < 3.0)
        assert np.allclose(pa * 10, np.round(pa * 10))  # rounded to 0.1 px


def test_seeds_are_made_with_the_true_not_the_nominal_geometry():
    # With header error, the nominal projection of B is off by many pixels.
    errs_true, errs_nominal = [], []
    for seed in range(6):
        case = ph.make_phantom("data2", seed, render=False)
        _, pb, _ = case.seeds.correspondences()
        X = case.truth.features_world
        errs_true.append(np.linalg.norm(pb - case.view_b_true.project(X), axis=1).mean())
        errs_nominal.append(np.linalg.norm(pb - case.view_b_nominal.project(X), axis=1).mean())
    assert max(errs_true) < 2.0
    assert np.mean(errs_nominal) > 3.0 * np.mean(errs_true)


@pytest.mark.parametrize("pct", [10.0, 25.0, 50.0, 75.0])
def test_stenosis_minimum_radius(pct):
    t = ph.make_phantom("data2", 1, stenosis_pct=pct, render=False).truth
    ref_r = t.reference_diameter_mm / 2.0
    lesion = np.abs(t.segment_s_mm - t.stenosis_s_mm) <= t.stenosis_length_mm / 2
    r_lesion = t.segment_radius_mm[lesion]
    assert r_lesion.min() == pytest.approx((1 - pct / 100) * ref_r, rel=0.02)
    assert t.mld_mm == pytest.approx(2 * r_lesion.min())
    assert 6.0 <= t.stenosis_length_mm <= 12.0
    # The narrowest point of the lesion is its centre (within a sample or two).
    i = np.argmin(r_lesion)
    assert abs(t.segment_s_mm[lesion][i] - t.stenosis_s_mm) < 0.5
    # Outside the lesion the lumen is the smooth undiseased taper.
    healthy = ph.make_phantom("data2", 1, stenosis_pct=0.0, render=False).truth
    assert np.allclose(t.segment_radius_mm[~lesion], healthy.segment_radius_mm[~lesion])
    assert np.all(t.segment_radius_mm <= healthy.segment_radius_mm + 1e-12)


def test_segment_volume_against_an_independent_integral():
    t0 = ph.make_phantom("data1", 2, stenosis_pct=0.0, render=False).truth
    f = 0.6
    t = ph.make_phantom("data1", 2, stenosis_pct=100 * f, render=False).truth
    for tr in (t0, t):
        v = np.pi * simpson(tr.segment_radius_mm**2, x=tr.segment_s_mm)
        assert tr.segment_volume_mm3 == pytest.approx(v, rel=1e-4)
    # A cosine stenosis r_ref (1 - f g) removes pi r^2 Ls (f - 3 f^2 / 8) of lumen.
    r_c = t.reference_diameter_mm / 2
    removed = np.pi * r_c**2 * t.stenosis_length_mm * (f - 3 * f**2 / 8)
    assert t0.segment_volume_mm3 - t.segment_volume_mm3 == pytest.approx(removed, rel=0.02)


def test_projected_radius_helper():
    case = ph.make_phantom("data1", 0, render=False)
    t = case.truth
    r_px = t.segment_radius_px(case.view_a)
    X = t.segment_X_world[0]
    expected = t.segment_radius_mm[0] * 1200.0 / case.view_a.depth_mm(X)[0] / 0.390625
    assert r_px[0] == pytest.approx(expected)


def test_bad_requests_raise_value_errors():
    with pytest.raises(ValueError, match="unknown phantom preset"):
        ph.make_phantom("data9")
    with pytest.raises(ValueError, match="stenosis_pct"):
        ph.make_phantom("data1", stenosis_pct=100.0)


# ------------------------------------------------------------ path length
def test_path_length_of_a_cylinder_perpendicular_to_the_rays():
    view = small_ap_view()
    r = 2.0
    L = ph.path_length_image(view, [straight([-20, 0, 0], [20, 0, 0], r)])
    assert L[50, 50] == pytest.approx(2 * r, abs=1e-9)  # central ray through the axis
    # Off-axis pixels: the exact chord of the ray through the cylinder.
    rows = np.arange(40, 61)
    pixels = np.column_stack([np.full(len(rows), 50.0), rows])
    assert np.allclose(L[rows, 50], chord_x_cylinder(view, pixels, r), atol=1e-6)
    assert L[20, 50] == 0.0


def test_path_length_union_and_crossings():
    view = small_ap_view()
    v1 = straight([-20, 0, 0], [20, 0, 0], 2.0)
    # Overlapping copies of the same tube count once.
    L_twice = ph.path_length_image(view, [v1, v1])
    assert L_twice[50, 50] == pytest.approx(4.0, abs=1e-9)
    # A second vessel crossing at another depth adds its own chord.
    v2 = straight([0, 10, -20], [0, 10, 20], 1.5)
    L = ph.path_length_image(view, [v1, v2])
    assert L[50, 50] == pytest.approx(4.0 + 3.0, abs=1e-9)
    assert L[50, 60] == pytest.approx(4.0, abs=0.05)  # away from the crossing
    # A tapered tube: piecewise-linear radius, exact at the axis pixel.
    v3 = straight([-10, 0, 0], [10, 0, 0], 1.0, 2.0)
    L3 = ph.path_length_image(view, [v3])
    assert L3[50, 50] == pytest.approx(3.0, abs=1e-6)


def test_path_length_of_a_foreshortened_tube_along_the_ray():
    view = small_ap_view()
    tube = straight([0, -5, 0], [0, 5, 0], 1.0)
    L = ph.path_length_image(view, [tube])
    assert L[50, 50] == pytest.approx(10.0 + 2.0, abs=1e-6)  # length plus the two caps


def test_supersampled_path_length_keeps_the_area():
    # Integral of L over the image = volume / pixel footprint at the vessel depth.
    view = small_ap_view(size=121)
    r = 1.0
    tube = straight([-5, 0, 0], [5, 0, 0], r)
    L = ph.path_length_image(view, [tube], supersample=4)
    volume = np.pi * r**2 * 10.0 + 4.0 / 3.0 * np.pi * r**3
    footprint = (0.3 * 750.0 / 1000.0) ** 2  # pixel area at the isocenter
    assert L.sum() * footprint == pytest.approx(volume, rel=0.02)


# ------------------------------------------------------------ rendering
def test_rendered_images(rendered):
    case = rendered
    for image, view in ((case.image_a, case.view_a), (case.image_b, case.view_b_true)):
        assert image.dtype == np.float32 and image.shape == (512, 512)
        assert image.min() >= 0 and image.max() <= 4095
        assert np.array_equal(image, np.round(image))
        assert image[:3].mean() < 100  # black collimator border
        p = case.truth.segment_px(view)
        t = np.gradient(p, axis=0)
        n = np.column_stack([-t[:, 1], t[:, 0]]) / np.linalg.norm(t, axis=1)[:, None]

        def sample(points, image=image):
            ij = np.round(points).astype(int)
            return image[ij[:, 1], ij[:, 0]]

        centre = np.median(sample(p))
        sides = np.median(np.concatenate([sample(p + 10 * n), sample(p - 10 * n)]))
        assert centre < 0.9 * sides


def test_render_does_not_change_the_geometry(rendered):
    plain = ph.make_phantom("data1", 3, stenosis_pct=50.0, render=False)
    assert plain.seeds == rendered.seeds
    assert np.array_equal(plain.truth.segment_X_world, rendered.truth.segment_X_world)


def test_rendering_is_deterministic():
    a = ph.make_phantom("static", 2, n_frames=3)
    b = ph.make_phantom("static", 2, n_frames=3)
    assert np.array_equal(a.image_a, b.image_a) and np.array_equal(a.frames_b, b.frames_b)
    assert a.frames_a.shape == (3, 512, 512)
    assert np.array_equal(a.frames_a[a.frame_index], a.image_a)
    # Contrast washes in: the first frame's vessel is fainter than the chosen one's.
    p = np.round(a.truth.segment_px(a.view_a)).astype(int)
    first = a.frames_a[0][p[:, 1], p[:, 0]].mean()
    chosen = a.image_a[p[:, 1], p[:, 0]].mean()
    assert chosen < first


# ------------------------------------------------------------ files
def test_write_phantom_case_round_trip(rendered, tmp_path):
    paths = ph.write_phantom_case(rendered, tmp_path / "case")
    assert set(paths) == {"a", "b", "seeds", "truth"}
    assert load_seeds(paths["seeds"]) == rendered.seeds
    truth = ph.load_truth(paths["truth"])
    assert np.allclose(truth.segment_X_world, rendered.truth.segment_X_world, atol=1e-5)
    assert np.allclose(truth.correction_rotvec, rendered.truth.correction_rotvec)
    assert truth.feature_names == rendered.truth.feature_names
    assert truth.segment_volume_mm3 == pytest.approx(rendered.truth.segment_volume_mm3)
    doc = json.loads(paths["truth"].read_text())
    assert ViewGeometry.from_dict(doc["view_b_true"]) == rendered.view_b_true
    assert ViewGeometry.from_dict(doc["view_b_nominal"]) == rendered.view_b_nominal

    from recon import dicom_io

    load = getattr(dicom_io, "load_angiogram", None)
    if load is None:
        pytest.skip("recon.dicom_io.load_angiogram is not there yet")
    for key, view, image in (
        ("a", rendered.view_a, rendered.image_a),
        ("b", rendered.view_b_nominal, rendered.image_b),
    ):
        angio = load(paths[key])
        assert angio.geometry == view  # the NOMINAL header for b
        assert np.array_equal(np.asarray(angio.image, dtype=np.float32), image)


def test_load_truth_names_the_bad_file(tmp_path):
    bad = tmp_path / "truth.json"
    bad.write_text("{}")
    with pytest.raises(ph.PhantomError, match="truth.json"):
        ph.load_truth(bad)


def test_no_waypoint_crowds_another_click() -> None:
    """data1/128 foreshortens the distal quarter in view B onto its end: no waypoint there."""
    for preset, seed in (("data1", 128), ("static", 7), ("data3", 110)):
        seg = ph.make_phantom(preset, seed, render=False).seeds.segments[0]
        for clicks in (seg.a, seg.b):
            gaps = np.linalg.norm(np.diff(np.asarray(clicks), axis=0), axis=1)
            assert len(clicks) >= 2 and gaps.min() >= ph.WAYPOINT_MIN_GAP_PX, (preset, seed)
