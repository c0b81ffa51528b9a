"""The densitometric area and the ellipse from two calipers plus that area."""

from dataclasses import replace

import numpy as np
from support import centerline_3d, straight

from recon.correspond.triangulation import radius_mm_eq11
from recon.geometry import ViewGeometry
from recon.lumen.densitometry import (
    calibrate_attenuation,
    ellipse_from_calipers,
    fill_ratios,
    with_fill_ratios,
)
from recon.lumen.surface import elliptic_cross_sections, intersection_directions

VIEW_A = ViewGeometry(-30.0, 0.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)
VIEW_B = ViewGeometry(40.0, 15.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)


def support(major, minor, major_dir, line):
    """Half caliper width (M,) of ellipses along unit lines (M, 3)."""
    c = np.einsum("ij,ij->i", line, major_dir)
    return np.sqrt(major**2 * c**2 + minor**2 * (1.0 - c**2))


def test_two_calipers_and_the_area_fix_the_ellipse():
    a, b, phi = 1.5, 0.75, np.deg2rad(35.0)
    theta = np.deg2rad([70.0, 100.0, 135.0])
    h_a = np.hypot(a * np.cos(phi), b * np.sin(phi)) * np.ones(3)
    h_b = np.hypot(a * np.cos(theta - phi), b * np.sin(theta - phi))
    e = ellipse_from_calipers(h_a, h_b, theta, np.full(3, np.pi * a * b))
    assert not e.clipped.any()
    np.testing.assert_allclose(e.area_mm2, np.pi * a * b)
    np.testing.assert_allclose(np.sqrt(e.m11 * e.m22 - e.m12**2), a * b, rtol=1e-12)
    u = np.stack([np.cos(theta), np.sin(theta)])
    np.testing.assert_allclose(np.sqrt(e.m11 * u[0] ** 2 + 2 * e.m12 * u[0] * u[1]
                                       + e.m22 * u[1] ** 2), h_b, rtol=1e-12)
    np.testing.assert_allclose(np.sqrt(e.m11), h_a, rtol=1e-12)
    # an area above the one of the ellipse inscribed in the calipers' parallelogram is cut
    too_big = ellipse_from_calipers(h_a, h_b, theta, np.full(3, 50.0))
    assert too_big.clipped.all()
    np.testing.assert_allclose(too_big.area_mm2, np.pi * h_a * h_b / np.sin(theta))


def test_eccentric_section_area_recovered_where_the_two_caliper_section_misses():
    """A 1.5 x 0.75 mm lumen at 20 degrees to view A's line: the paper's construction
    (the shorter half-width taken as a point of the ellipse) misses its area by more
    than 40 %; with the densitometric fill ratios the section has the true area."""
    X = straight(direction=(0.2, 0.3, 0.93), origin=(0.0, 0.0, 0.0))
    cl = centerline_3d(X, 1.0)
    l_a = intersection_directions(cl.X_world, cl.tangents, VIEW_A)
    l_b = intersection_directions(cl.X_world, cl.tangents, VIEW_B)
    e2 = np.cross(cl.tangents, l_a)
    phi = np.deg2rad(20.0)
    major_dir = np.cos(phi) * l_a + np.sin(phi) * e2
    a, b = 1.5, 0.75
    h_a, h_b = support(a, b, major_dir, l_a), support(a, b, major_dir, l_b)
    cl = replace(cl, radius_a_mm=h_a, radius_b_mm=h_b)
    true_area = np.pi * a * b
    old = elliptic_cross_sections(cl, VIEW_A, VIEW_B).area_mm2
    assert np.all(np.abs(old / true_area - 1.0) > 0.4)
    fills = replace(cl, fill_a=true_area / (np.pi * h_a**2), fill_b=true_area / (np.pi * h_b**2))
    new = elliptic_cross_sections(fills, VIEW_A, VIEW_B)
    np.testing.assert_allclose(new.area_mm2, true_area, rtol=1e-9)
    np.testing.assert_allclose(support(new.major_mm, new.minor_mm, new.major_axis, l_a), h_a,
                               rtol=1e-9)
    np.testing.assert_allclose(support(new.major_mm, new.minor_mm, new.major_axis, l_b), h_b,
                               rtol=1e-9)


def test_round_lumen_keeps_the_two_caliper_section():
    cl = centerline_3d(straight(), 1.2)
    ones = np.ones(len(cl.X_world))
    plain = elliptic_cross_sections(cl, VIEW_A, VIEW_B)
    dens = elliptic_cross_sections(replace(cl, fill_a=1.3 * ones, fill_b=0.8 * ones),
                                   VIEW_A, VIEW_B)
    np.testing.assert_array_equal(dens.area_mm2, plain.area_mm2)


def _depths(cl, area, mu_a, mu_b):
    """The profile-fit depths b_k = mu_k m_k A / (pi h_k^2 sin alpha_k) (module docstring)."""
    out = []
    for view, h, mu in ((VIEW_A, cl.radius_a_mm, mu_a), (VIEW_B, cl.radius_b_mm, mu_b)):
        ray = cl.X_world - view.source_world
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        sin_alpha = np.linalg.norm(np.cross(ray, cl.tangents), axis=1)
        m = radius_mm_eq11(np.ones(len(cl.X_world)), cl.X_world, view)
        out.append(mu * m * area / (np.pi * h**2 * sin_alpha))
    return out


def test_fill_ratios_known_answer_with_fading_contrast():
    """Round lumen of 1.4 mm except an eccentric stretch (areas and calipers known);
    the attenuation per mm fades linearly along the vessel, differently per view.
    The calibration on the round points recovers fill = A / (pi h^2) everywhere."""
    X = straight(length=40.0, direction=(0.2, 0.3, 0.93), origin=(0.0, 0.0, 0.0))
    cl = centerline_3d(X, 1.4)
    s = cl.s_mm
    lesion = np.abs(s - 20.0) < 4.0
    h_a = np.where(lesion, 0.8, 1.4)
    h_b = np.where(lesion, 1.1, 1.4)
    area = np.where(lesion, 2.2, np.pi * 1.4**2)
    cl = replace(cl, radius_a_mm=h_a, radius_b_mm=h_b)
    mu_a = 0.11 * (1.0 - 0.3 * s / s[-1])
    mu_b = 7.0 * (1.0 - 0.2 * s / s[-1])
    depth_a, depth_b = _depths(cl, area, mu_a, mu_b)
    fills = fill_ratios(cl.X_world, cl.tangents, s, h_a, h_b, depth_a, depth_b, VIEW_A, VIEW_B)
    assert fills is not None
    np.testing.assert_allclose(fills[0], area / (np.pi * h_a**2), rtol=1e-9)
    np.testing.assert_allclose(fills[1], area / (np.pi * h_b**2), rtol=1e-9)
    # the pipeline stage, then the section: the true area in the lesion
    staged = with_fill_ratios(replace(cl, depth_a=depth_a, depth_b=depth_b), VIEW_A, VIEW_B)
    sec = elliptic_cross_sections(staged, VIEW_A, VIEW_B)
    np.testing.assert_allclose(sec.area_mm2[lesion], 2.2, rtol=1e-9)


def test_calibration_needs_round_points_and_ignores_outliers():
    s = np.linspace(0.0, 30.0, 121)
    rho = 0.1 - 0.001 * s
    bad = rho.copy()
    bad[50:60] *= 1.8  # an eccentric stretch that slipped into the round mask
    mu = calibrate_attenuation(s, bad, np.ones(len(s), dtype=bool))
    np.testing.assert_allclose(mu, rho, rtol=1e-9)
    few = np.zeros(len(s), dtype=bool)
    few[:10] = True
    assert calibrate_attenuation(s, rho, few) is None


def test_fill_draws_span_the_two_views_disagreement():
    """Round fills exactly 1 (no calibration scatter): the draws are the common factor
    1 +- |A_a - A_b| / (A_a + A_b), the same for both views, reaching both ends."""
    from recon.lumen.densitometry import fill_draws

    cl = centerline_3d(straight(), 1.0)
    m = len(cl.X_world)
    lesion = np.arange(m) == m // 2
    r_b = np.where(lesion, 0.5, 1.0)
    fill_a = np.where(lesion, 0.36, 1.0)  # A_a = 0.36 pi, A_b = 0.25 * 1.2 pi = 0.30 pi
    fill_b = np.where(lesion, 1.2, 1.0)
    cl = replace(cl, radius_b_mm=r_b, fill_a=fill_a, fill_b=fill_b)
    draws = fill_draws(cl, 4000, np.random.default_rng(0))
    assert draws.shape == (4000, 2, m)
    np.testing.assert_allclose(draws[:, :, ~lesion], 1.0)
    gap = 0.06 / 0.66
    at = draws[:, 0, m // 2]
    np.testing.assert_allclose(draws[:, 0, m // 2], draws[:, 1, m // 2])
    assert at.min() >= 1 - gap - 1e-12 and at.max() <= 1 + gap + 1e-12
    assert at.min() < 1 - 0.95 * gap and at.max() > 1 + 0.95 * gap


def test_rendered_eccentric_lesion_area_from_the_images():
    """A 1.5 x 0.75 mm elliptic lesion (12 mm long, 2 mm reference) rendered into the
    static pair, traced, matched, triangulated: at the lesion centre the two-caliper
    section is 45 % off here, the densitometric one within 12 %."""
    from recon.correspond.matching import match_centerlines
    from recon.correspond.triangulation import build_centerline_3d
    from recon.synth import PRESETS
    from recon.synth.elliptic_tube import EllipticTube, render_tube
    from recon.trace.centerline import compute_vesselness, trace_segment

    view_a, view_b = PRESETS["static"].view_a, PRESETS["static"].view_b
    T = np.array([0.2, 0.3, 0.93]) / np.linalg.norm([0.2, 0.3, 0.93])
    l_a = intersection_directions(np.zeros((1, 3)), T[None], view_a)[0]
    phi = np.deg2rad(45.0)
    major = np.cos(phi) * l_a + np.sin(phi) * np.cross(T, l_a)
    tube = EllipticTube(np.zeros(3), T, major, 2.0, 1.5, 0.75, lesion_length_mm=12.0,
                        mu_per_mm=0.1)
    rng = np.random.default_rng(0)
    ends = np.array([[-15.0], [15.0]]) * T[None]
    traces = []
    for view in (view_a, view_b):
        image = render_tube(rng, view, tube)
        pixel_mm = view.pixel_mm_at_isocenter
        traces.append(trace_segment(image, view.project(ends), pixel_mm=pixel_mm,
                                    vesselness=compute_vesselness(image, pixel_mm=pixel_mm)))
    assert traces[0].depth is not None and traces[0].depth.shape == traces[0].radius_px.shape
    cl = build_centerline_3d(match_centerlines(traces[0], traces[1], view_a, view_b),
                             view_a, view_b)
    i = int(np.argmin(np.linalg.norm(cl.X_world, axis=1)))
    two = elliptic_cross_sections(cl, view_a, view_b).area_mm2[i] / tube.area_mm2 - 1.0
    dens_cl = with_fill_ratios(cl, view_a, view_b)
    assert dens_cl.fill_a is not None
    dens = elliptic_cross_sections(dens_cl, view_a, view_b).area_mm2[i] / tube.area_mm2 - 1.0
    assert abs(two) > 0.3
    assert abs(dens) < 0.12
