"""Tests of recon.trace.centerline on synthetic tubes with known centre and radius."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage as ndi
from scipy.spatial import cKDTree

from recon.trace.centerline import (
    TraceError,
    VesselnessMap,
    compute_vesselness,
    snap_click,
    trace_segment,
)

DATA = Path(__file__).resolve().parents[2] / "data"


# ------------------------------------------------------------------ helpers
def render(
    shape: tuple[int, int],
    tubes: list[tuple[np.ndarray, np.ndarray]],
    *,
    noise: float = 0.0,
    seed: int = 0,
    border_px: int = 0,
    blur_px: float = 0.7,
) -> np.ndarray:
    """Beer-Lambert tubes (centre (M, 2) dense, radius (M,)) blurred by sigma ``blur_px``.

    I = 1000 exp(-0.08 * chord), chord = 2 sqrt(r^2 - d^2) averaged over each pixel's
    area (4 x 4 rays: a detector integrates over its pixels); optional black border.
    """
    h, w = shape
    rr, cc = np.mgrid[0:h, 0:w]
    sub = (np.arange(4) + 0.5) / 4 - 0.5
    line = np.zeros(h * w)
    for centre, radius in tubes:
        tree = cKDTree(centre)
        for dy in sub:
            for dx in sub:
                pix = np.column_stack([(cc + dx).ravel(), (rr + dy).ravel()])
                d, i = tree.query(pix)
                line += 2.0 * np.sqrt(np.clip(radius[i] ** 2 - d**2, 0.0, None)) / 16.0
    img = ndi.gaussian_filter(1000.0 * np.exp(-0.08 * line.reshape(h, w)), blur_px)
    if noise:
        img = img + np.random.default_rng(seed).normal(0.0, noise, img.shape)
    if border_px:
        img[:border_px] = img[-border_px:] = 5.0
        img[:, :border_px] = img[:, -border_px:] = 5.0
    return img


def segment(p: tuple[float, float], q: tuple[float, float], n: int = 3000) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.asarray(p, float) * (1.0 - t) + np.asarray(q, float) * t


def arc(centre: tuple[float, float], r: float, a0: float, a1: float, n: int = 4000) -> np.ndarray:
    t = np.linspace(a0, a1, n)
    return np.column_stack([centre[0] + r * np.cos(t), centre[1] + r * np.sin(t)])


def distance_to(points: np.ndarray, curve: np.ndarray) -> np.ndarray:
    return cKDTree(curve).query(points)[0]


# --------------------------------------------------------------- vesselness
def test_vesselness_on_tube_not_on_border() -> None:
    line = segment((20, 50), (100, 50))
    img = render((100, 120), [(line, np.full(len(line), 2.5))], noise=5.0, border_px=6)
    vmap = compute_vesselness(img)
    assert isinstance(vmap, VesselnessMap)
    assert vmap.response.shape == img.shape and vmap.response.dtype == np.float32
    assert vmap.scale_px.dtype == np.float32 and vmap.valid.dtype == bool
    assert 0.0 <= vmap.response.min() and vmap.response.max() <= 1.0
    assert vmap.response[50, 40:80].min() > 0.5
    assert not vmap.valid[:10].any() and not vmap.valid[:, -10:].any()
    assert vmap.response[~vmap.valid].max() == 0.0
    # background well away from the tube barely responds
    assert np.percentile(vmap.response[20:35, 20:100], 99) < 0.2


def test_vesselness_does_not_modify_input() -> None:
    line = segment((10, 30), (50, 30))
    img = render((60, 60), [(line, np.full(len(line), 2.0))])
    before = img.copy()
    compute_vesselness(img)
    np.testing.assert_array_equal(img, before)


# ----------------------------------------------------------------- snapping
def test_snap_finds_a_faint_vessel_beside_a_strong_one() -> None:
    """The display response is normalised per image, so a thin distal vessel stays
    low there; the ridge measure the tracing uses is normalised by the background,
    so the faint vessel scores like the strong one and a click on it snaps onto it."""
    strong, faint = segment((10, 30), (150, 30)), segment((10, 90), (150, 90))
    img = render((120, 160), [(strong, np.full(len(strong), 5.0)),
                              (faint, np.full(len(faint), 1.2))], noise=2.0)
    vmap = compute_vesselness(img)
    assert vmap.response[86:95, 40:120].max() < 0.15  # below the display threshold
    assert vmap.ridge[86:95, 40:120].max() > 0.8 * vmap.ridge[26:35, 40:120].max()
    snapped, dist = snap_click(vmap, (80.0, 92.5))
    assert abs(snapped[1] - 90.0) <= 1.0 and dist < 3.5
    with pytest.raises(TraceError, match="from any vessel"):
        snap_click(vmap, (80.0, 60.0))  # empty background between them


def test_snap_click_moves_across_not_along() -> None:
    line = segment((10, 40), (110, 40))
    img = render((80, 120), [(line, np.full(len(line), 3.0))], noise=5.0)
    vmap = compute_vesselness(img)
    snapped, dist = snap_click(vmap, (60.0, 44.0))
    assert abs(snapped[1] - 40.0) <= 1.0
    assert abs(snapped[0] - 60.0) <= 1.0
    assert dist == pytest.approx(np.hypot(*(snapped - (60.0, 44.0))))
    with pytest.raises(TraceError, match=r"px from any vessel"):
        snap_click(vmap, (60.0, 65.0), max_distance_px=8.0)


# ------------------------------------------------------------------ tracing
@pytest.mark.parametrize("radius_px", [2.0, 4.0])
def test_trace_curved_tube_centre_and_radius(radius_px: float) -> None:
    curve = arc((100.0, 180.0), 120.0, -2.2, -0.9)
    img = render((180, 200), [(curve, np.full(len(curve), radius_px))], noise=8.0)
    clicks = np.array([curve[150], curve[2000] + (1.5, -1.0), curve[-150]])
    cl = trace_segment(img, clicks, view="A")
    d = distance_to(cl.points_px, curve)
    assert np.sqrt(np.mean(d**2)) < 0.15
    assert d.max() < 0.4
    inner = slice(6, -6)
    assert np.mean(np.abs(cl.radius_px[inner] - radius_px)) < 0.2
    steps = np.linalg.norm(np.diff(cl.points_px, axis=0), axis=1)
    assert np.allclose(steps, 0.5, atol=0.05)
    # proximal to distal, ends at the clicks
    assert np.linalg.norm(cl.points_px[0] - clicks[0]) < 1.0
    assert np.linalg.norm(cl.points_px[-1] - clicks[-1]) < 1.0
    assert cl.clicks_px.shape == (3, 2)
    # brightness is the image value on the centreline: darker than the background
    assert cl.brightness.shape == (len(cl.points_px),)
    assert np.all(cl.brightness < 0.9 * np.median(img))


def test_trace_stays_on_vessel_through_crossing() -> None:
    a = segment((10, 20), (150, 110))
    b = segment((10, 110), (150, 20))
    img = render((130, 160), [(a, np.full(len(a), 3.0)), (b, np.full(len(b), 3.0))],
                 noise=5.0)
    cl = trace_segment(img, [a[200], a[-200]])
    d = distance_to(cl.points_px, a)
    assert d.max() < 1.0
    assert np.sqrt(np.mean(d**2)) < 0.3


def test_trace_follows_clicked_one_of_parallel_vessels() -> None:
    upper = segment((10, 40), (150, 40))
    lower = segment((10, 51), (150, 51))  # 6 px of background between the lumens
    tubes = [(upper, np.full(len(upper), 2.5)), (lower, np.full(len(lower), 2.5))]
    img = render((90, 160), tubes, noise=5.0)
    for line, row in ((upper, 40.0), (lower, 51.0)):
        cl = trace_segment(img, [(15.0, row), (80.0, row + 2.0), (145.0, row)])
        assert distance_to(cl.points_px, line).max() < 0.4
        assert np.mean(np.abs(cl.radius_px[6:-6] - 2.5)) < 0.2


def test_trace_keeps_a_stenosis() -> None:
    line = segment((10, 40), (150, 40))
    x = line[:, 0]
    radius = 4.0 - 2.0 * np.exp(-0.5 * ((x - 80.0) / 4.0) ** 2)  # 50 % over ~16 px
    img = render((80, 160), [(line, radius)], noise=3.0)
    cl = trace_segment(img, [(15.0, 40.0), (145.0, 40.0)])
    at = cl.points_px[:, 0]
    assert cl.radius_px[np.abs(at - 80.0) < 1.0].min() == pytest.approx(2.0, abs=0.4)
    assert np.median(cl.radius_px[np.abs(at - 30.0) < 5.0]) == pytest.approx(4.0, abs=0.3)


def test_reuses_vesselness_and_does_not_modify_inputs() -> None:
    line = segment((10, 30), (90, 30))
    img = render((60, 100), [(line, np.full(len(line), 2.5))])
    clicks = np.array([[15.0, 30.0], [85.0, 31.0]])
    img0, clicks0 = img.copy(), clicks.copy()
    vmap = compute_vesselness(img)
    cl1 = trace_segment(img, clicks, vesselness=vmap)
    cl2 = trace_segment(img, clicks)
    np.testing.assert_allclose(cl1.points_px, cl2.points_px)
    np.testing.assert_array_equal(img, img0)
    np.testing.assert_array_equal(clicks, clicks0)


# ---------------------------------------------------------------- bad input
@pytest.fixture(scope="module")
def two_tubes() -> tuple[np.ndarray, VesselnessMap]:
    left = segment((10, 30), (50, 30))
    right = segment((90, 30), (130, 30))
    img = render((60, 140), [(left, np.full(len(left), 2.5)), (right, np.full(len(right), 2.5))])
    return img, compute_vesselness(img)


@pytest.mark.parametrize(
    ("clicks", "pattern"),
    [
        ([[15.0, 30.0], [200.0, 30.0]], r"^view B: click 2 \(distal end\) at \(200.0, 30.0\) is "
                                        r"outside the 140x60 image$"),
        ([[15.0, 30.0], [15.5, 30.0]], r"^view B: clicks 1 and 2 are 0.5 px apart"),
        ([[15.0, 30.0]], r"^view B: need at least 2 clicks"),
        ([[15.0, 30.0], [30.0, 50.0]], r"^view B: click 2 \(distal end\): click at \(30.0, 50.0\)"
                                       r" is .* px from any vessel"),
        ([[15.0, 30.0], [120.0, 30.0]], r"^view B: no vessel path between click 1 and click 2"),
    ],
)
def test_bad_clicks_raise_one_line_trace_error(
    two_tubes: tuple[np.ndarray, VesselnessMap], clicks: list, pattern: str
) -> None:
    img, vmap = two_tubes
    with pytest.raises(TraceError, match=pattern) as info:
        trace_segment(img, clicks, vesselness=vmap, view="B")
    assert "\n" not in str(info.value)
    assert isinstance(info.value, ValueError)


# ---------------------------------------------------------------- real data
REAL_CLICKS = {  # a clear tube in each view of the static phantom (col, row)
    "IM7.dcm": [(330.0, 335.0), (205.0, 465.0)],
    "IM8.dcm": [(215.0, 240.0), (380.0, 248.0)],
}


@pytest.mark.parametrize("name", sorted(REAL_CLICKS))
def test_real_static_phantom_trace_stays_on_tube(name: str) -> None:
    from recon.io import load_angiogram

    image = np.asarray(load_angiogram(DATA / name).image, dtype=float)
    vmap = compute_vesselness(image)
    assert vmap.response[~vmap.valid].max() == 0.0
    assert not vmap.valid[:, :8].any() and not vmap.valid[-6:].any()  # collimator border
    clicks = np.asarray(REAL_CLICKS[name])
    cl = trace_segment(image, clicks, vesselness=vmap)
    resp = ndi.map_coordinates(vmap.response, cl.points_px[:, ::-1].T, order=1)
    assert resp.mean() > 0.5 and resp.min() > 0.3
    assert 3.0 <= np.median(cl.radius_px) <= 12.0
    assert np.linalg.norm(cl.points_px[0] - clicks[0]) < 3.0
    assert np.linalg.norm(cl.points_px[-1] - clicks[-1]) < 3.0
    # the centreline is darker than the tube's surroundings
    assert np.median(cl.brightness) < np.median(image[vmap.valid]) - 20.0


# ------------------------------------------------------------------ phantom
def test_phantom_trace_matches_projected_truth() -> None:
    from recon.synth import make_phantom

    case = make_phantom("data2", 1, render=True)
    X_world, radius_mm = case.truth.vessels[0]  # the whole main vessel
    pts = case.view_a.project(X_world)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    s_dense = np.arange(0.0, s[-1], 0.05)
    dense = np.column_stack([np.interp(s_dense, s, pts[:, 0]), np.interp(s_dense, s, pts[:, 1])])
    radius_px = radius_mm * case.view_a.sid_mm / case.view_a.depth_mm(X_world) / float(
        np.mean(case.view_a.pixel_spacing_mm)
    )
    cl = trace_segment(case.image_a, case.seeds.segments[0].a, view="A")
    dist, nearest = cKDTree(dense).query(cl.points_px)
    assert np.sqrt(np.mean(dist**2)) < 0.8
    inner = slice(6, -6)  # 3 px at both ends
    r_true = np.interp(s_dense, s, radius_px)[nearest[inner]]
    assert np.mean(np.abs(cl.radius_px[inner] - r_true)) < 0.4


# ------------------------------------------------ overlaps and re-centring
def test_trace_ignores_a_diverging_neighbour_that_overlaps_it() -> None:
    # A thinner vessel leaves the clicked one at a small angle: for ~50 px the two
    # lumens overlap and the profile looks like one wide tube. The old single-pass
    # fit was pulled ~2 px (RMS 0.8 px) towards the neighbour.
    main = segment((10, 50), (170, 50))
    branch = segment((40, 50), (130, 60))
    img = render((100, 180), [(main, np.full(len(main), 4.5)), (branch, np.full(len(branch), 3.0))],
                 noise=5.0)
    cl = trace_segment(img, [(15.0, 50.0), (90.0, 51.0), (165.0, 50.0)])
    d = distance_to(cl.points_px, main)
    assert np.sqrt(np.mean(d**2)) < 0.6
    assert d.max() < 1.5
    # the far side of the overlap, where the vessels have separated, is exact
    beyond = cl.points_px[:, 0] > 140.0
    assert d[beyond].max() < 0.4


def test_limit_runs_marks_only_long_one_sided_runs() -> None:
    from recon.trace.centerline import _MAX_SHIFT_PX, _limit_runs

    m = _MAX_SHIFT_PX
    shift = np.array([0.1, m, m, m, m, m, 0.0, -m, -m, m, -m, -m, -m, -m, -m, -m])
    expected = np.array([0, 1, 1, 1, 1, 1, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1], dtype=float)
    np.testing.assert_array_equal(_limit_runs(shift, min_run=5), expected)


def test_reliability_downweights_wide_or_poor_fits() -> None:
    from recon.trace.centerline import _reliability

    n = 200
    radius = np.full(n, 5.0)
    rss = np.full(n, 1e-4)
    radius[80:110] = 7.5  # a stretch fitted as one wide tube (an overlap)
    rss[150:155] = 5e-3  # a stretch the model does not fit
    fitted = np.ones(n, dtype=bool)
    fitted[30] = False
    w = _reliability(radius, rss, fitted)
    assert w.shape == (n,)
    clean = np.ones(n, dtype=bool)
    clean[[30, *range(80, 110), *range(150, 155)]] = False
    np.testing.assert_allclose(w[clean], 1.0)
    assert w[80:110].max() < 0.1
    assert w[150:155].max() < 0.1
    assert w[30] < 0.01


# ------------------------------------------------------- what the trace records
def test_trace_records_its_intensity_mapping_and_blur() -> None:
    line = segment((10, 40), (150, 40))
    img = render((80, 160), [(line, np.full(len(line), 3.0))], noise=3.0)
    cl = trace_segment(img, [(15.0, 40.0), (145.0, 40.0)], relationship="LIN",
                       pixel_mm=0.29)
    assert cl.intensity_mapping == "lin" and cl.intensity_power == 0.0
    assert cl.intensity_reason.startswith("PixelIntensityRelationship is LIN")
    assert "\n" not in cl.intensity_reason
    assert 0.5 < cl.blur_px < 1.2  # fitted around the nominal 0.7 px
    fixed = trace_segment(img, [(15.0, 40.0), (145.0, 40.0)], intensity="log",
                          estimate_blur=False)
    assert fixed.intensity_mapping == "log" and fixed.blur_px == pytest.approx(0.7)
    assert "set by the user" in fixed.intensity_reason
    with pytest.raises(ValueError, match="intensity must be one of"):
        trace_segment(img, [(15.0, 40.0), (145.0, 40.0)], intensity="gamma")


def test_a_blur_beyond_the_search_grid_is_found_and_the_radius_kept() -> None:
    # a blurred image intensifier: sigma 1.8 px (with the 4 x 4 pixel aperture, 1.82 px),
    # above the blur grid's last value (2.2 x 0.7 = 1.54 px), where the search once stopped
    line = segment((10, 40), (150, 40))
    img = render((80, 160), [(line, np.full(len(line), 3.0))], noise=2.0, blur_px=1.8)
    cl = trace_segment(img, [(15.0, 40.0), (145.0, 40.0)], relationship="LIN")
    assert cl.blur_px == pytest.approx(np.hypot(1.8, np.sqrt(1 / 12)), rel=0.1)
    inner = slice(len(cl.radius_px) // 5, -len(cl.radius_px) // 5)
    assert np.median(cl.radius_px[inner]) == pytest.approx(3.0, rel=0.03)


def test_robust_shift_gives_no_weight_to_fits_pulled_onto_a_neighbour() -> None:
    from recon.trace.centerline import _robust_shift

    rng = np.random.default_rng(3)
    n = 120
    true = 0.5 * np.sin(np.arange(n) / 15.0)  # a slowly varying offset (px)
    shift = true + rng.normal(0.0, 0.2, n)
    shift[50:56] += np.array([2.5, 3.5, 4.5, 4.0, 3.0, 2.5])  # a junction pulls six fits
    smooth, inlier, scatter = _robust_shift(shift, np.ones(n), np.full(n, 8.0))
    assert inlier[50:56].max() < 0.1
    assert np.median(inlier[np.r_[0:45, 60:n]]) > 0.9
    assert np.abs(smooth - true).max() < 0.35
    assert scatter == pytest.approx(0.2, abs=0.08)


def test_trace_of_a_wide_vessel_is_not_pulled_into_a_joining_branch() -> None:
    main = segment((10, 60), (250, 60))
    a = np.deg2rad(30.0)  # a branch joins the main vessel (radius 10 px) at 30 degrees
    branch = segment((128, 62), (128 - 90 * np.cos(a), 62 + 90 * np.sin(a)))
    img = render((140, 260), [(main, np.full(len(main), 10.0)),
                              (branch, np.full(len(branch), 8.0))], noise=15.0, seed=4)
    cl = trace_segment(img, [(20.0, 60.0), (240.0, 60.0)])
    assert distance_to(cl.points_px, main).max() < 1.0


@pytest.mark.xfail(strict=True, reason=(
    "issue 13, not solved: a neighbour overlapping one side pulls the profile fit's "
    "centre 1.7-2.2 px towards it (a walls-based centring fixed this case but moved the "
    "regular suite's medians beyond the 5 % rule; docs/benchmarks.md)"))
@pytest.mark.parametrize(("gap_px", "r_neighbour_px"), [(5.0, 4.0), (6.0, 3.0)])
def test_trace_is_not_pulled_by_a_neighbour_overlapping_one_side(gap_px: float,
                                                                 r_neighbour_px: float) -> None:
    # A thinner vessel comes in at an angle, runs 100 px beside the traced one with
    # their lumens overlapping in projection (centres gap_px apart, radii 5 and
    # r_neighbour_px), and leaves. A single-tube fit spans both.
    main = segment((10, 60), (330, 60))
    y = 60.0 - gap_px
    nb = np.vstack([segment((60, y - 25), (120, y), 800), segment((120, y), (220, y), 1500),
                    segment((220, y), (280, y - 25), 800)])
    img = render((120, 340), [(main, np.full(len(main), 5.0)),
                              (nb, np.full(len(nb), r_neighbour_px))], noise=5.0)
    cl = trace_segment(img, [(15.0, 60.0), (325.0, 60.0)])
    assert distance_to(cl.points_px, main).max() < 0.5
