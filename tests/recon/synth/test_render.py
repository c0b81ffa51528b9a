"""The phantom's renderer: exact path lengths and the X-ray images (recon/synth/render.py)."""

import numpy as np
import pytest

from recon.geometry import ViewGeometry
from recon.synth import make_phantom
from recon.synth.render import path_length_image


@pytest.fixture(scope="module")
def rendered():
    return make_phantom("data1", 3, stenosis_pct=50.0)


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


def test_path_length_of_a_cylinder_perpendicular_to_the_rays():
    view = small_ap_view()
    r = 2.0
    L = path_length_image(view, [straight([-20, 0, 0], [20, 0, 0], r)])
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
    L_twice = path_length_image(view, [v1, v1])
    assert L_twice[50, 50] == pytest.approx(4.0, abs=1e-9)
    # A second vessel crossing at another depth adds its own chord.
    v2 = straight([0, 10, -20], [0, 10, 20], 1.5)
    L = path_length_image(view, [v1, v2])
    assert L[50, 50] == pytest.approx(4.0 + 3.0, abs=1e-9)
    assert L[50, 60] == pytest.approx(4.0, abs=0.05)  # away from the crossing
    # A tapered tube: piecewise-linear radius, exact at the axis pixel.
    v3 = straight([-10, 0, 0], [10, 0, 0], 1.0, 2.0)
    L3 = path_length_image(view, [v3])
    assert L3[50, 50] == pytest.approx(3.0, abs=1e-6)


def test_path_length_of_a_foreshortened_tube_along_the_ray():
    view = small_ap_view()
    tube = straight([0, -5, 0], [0, 5, 0], 1.0)
    L = path_length_image(view, [tube])
    assert L[50, 50] == pytest.approx(10.0 + 2.0, abs=1e-6)  # length plus the two caps


def test_supersampled_path_length_keeps_the_area():
    # Integral of L over the image = volume / pixel footprint at the vessel depth.
    view = small_ap_view(size=121)
    r = 1.0
    tube = straight([-5, 0, 0], [5, 0, 0], r)
    L = path_length_image(view, [tube], supersample=4)
    volume = np.pi * r**2 * 10.0 + 4.0 / 3.0 * np.pi * r**3
    footprint = (0.3 * 750.0 / 1000.0) ** 2  # pixel area at the isocenter
    assert L.sum() * footprint == pytest.approx(volume, rel=0.02)


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
    plain = make_phantom("data1", 3, stenosis_pct=50.0, render=False)
    assert plain.seeds == rendered.seeds
    assert np.array_equal(plain.truth.segment_X_world, rendered.truth.segment_X_world)


def test_rendering_is_deterministic():
    a = make_phantom("static", 2, n_frames=3)
    b = make_phantom("static", 2, n_frames=3)
    assert np.array_equal(a.image_a, b.image_a) and np.array_equal(a.frames_b, b.frames_b)
    assert a.frames_a.shape == (3, 512, 512)
    assert np.array_equal(a.frames_a[a.frame_index], a.image_a)
    # Contrast washes in: the first frame's vessel is fainter than the chosen one's.
    p = np.round(a.truth.segment_px(a.view_a)).astype(int)
    first = a.frames_a[0][p[:, 1], p[:, 0]].mean()
    chosen = a.image_a[p[:, 1], p[:, 0]].mean()
    assert chosen < first


def test_the_footprint_prefilter_drops_no_hit(monkeypatch):
    """The image-plane prefilter only skips (cone, ray) pairs that miss: results are identical."""
    from dataclasses import replace

    import recon.synth.render as render

    case = make_phantom("data3", 102, render=False)
    prims = render._cone_chain(case.truth.vessels, [0.1] * len(case.truth.vessels))
    for view, ss in ((case.view_b_true, 2),
                     (replace(case.view_a, rows=1024, cols=1024,
                              pixel_spacing_mm=(0.154, 0.154)), 1)):
        att, length = render._attenuation_subpixels(view, prims, ss)
        monkeypatch.setattr(render, "_footprint_keep",
                            lambda view, P0, P1, rmax, ss, prim, flat: np.ones(len(prim), bool))
        att_all, length_all = render._attenuation_subpixels(view, prims, ss)
        monkeypatch.undo()
        assert np.array_equal(att, att_all) and np.array_equal(length, length_all)
        assert length.max() > 3.0
