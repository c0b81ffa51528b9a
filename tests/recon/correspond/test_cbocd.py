import numpy as np
import pytest

from recon.correspond.cbocd import (
    BETA_PX,
    brightness_ope,
    cbocd_descriptor,
    cbocd_parts,
    curvature_ope,
    postprocess_ope,
    px_to_points,
    trace_spacing_px,
)


def line(n=200, angle_deg=23.0, spacing=1.0):
    a = np.deg2rad(angle_deg)
    t = np.arange(n) * spacing
    return np.column_stack([100 + t * np.cos(a), 50 + t * np.sin(a)])


@pytest.mark.parametrize("angle", [0.0, 22.5, 23.0, 45.0, 67.5, 90.0, 137.0, 200.0])
def test_straight_line_is_all_other(angle):
    pts = line(angle_deg=angle)
    assert not curvature_ope(pts).any()
    desc = cbocd_descriptor(pts, np.full(len(pts), 80.0))
    assert np.all(desc == 2)


def test_straight_line_with_small_noise_is_straight():
    rng = np.random.default_rng(1)
    pts = line(angle_deg=31.0) + rng.normal(0, 0.05, (200, 2))
    assert curvature_ope(pts).mean() < 0.02


def test_tight_arc_is_curvature_ope():
    # straight, then a tight U-turn of radius 4 px, then straight back
    straight = line(60, angle_deg=0.0)
    th = np.linspace(-np.pi / 2, np.pi / 2, 14)[1:-1]
    centre = straight[-1] + [0, 4]
    arc = centre + 4 * np.column_stack([np.cos(th), np.sin(th)])
    back = straight[::-1] + [0, 8]
    pts = np.vstack([straight, arc, back])
    ope = curvature_ope(pts)
    n0 = len(straight)
    assert ope[n0 : n0 + len(arc)].mean() > 0.8
    assert not ope[: n0 - 8].any() and not ope[n0 + len(arc) + 8 :].any()
    desc = cbocd_descriptor(pts, np.full(len(pts), 80.0))
    assert np.all(desc[n0 + 1 : n0 + len(arc) - 1] == 4)


def test_gentle_arc_is_not_curvature_ope():
    th = np.linspace(0, np.pi / 2, 160)  # radius 100 px, ~1 px spacing
    pts = 100 * np.column_stack([np.cos(th), np.sin(th)])
    assert not curvature_ope(pts).any()


def test_brightness_dip_is_brightness_ope():
    n = 200
    b = np.linspace(90.0, 110.0, n)  # contrast washes out distally: a trend, not OPE
    b[80:110] -= 15.0  # darker (more contrast) on a foreshortened stretch
    ope = brightness_ope(b)
    assert ope[80:110].all()
    assert not ope[:78].any() and not ope[112:].any()
    desc = cbocd_descriptor(line(n), b)
    assert np.all(desc[80:110] == 3) and np.all(desc[:75] == 2)


def test_brightness_sign_for_bright_vessels():
    b = np.full(100, 50.0)
    b[40:60] += 20.0
    assert brightness_ope(b, vessel_dark=False)[40:60].all()
    assert not brightness_ope(b, vessel_dark=True).any()


def test_brightness_margin_suppresses_noise():
    rng = np.random.default_rng(0)
    b = 100 + rng.normal(0, 1.0, 500)
    assert brightness_ope(b, margin=0.0).mean() > 0.3  # the paper's raw rule: ~half
    assert brightness_ope(b).mean() < 0.05


def test_both_gives_five():
    straight = line(60, angle_deg=0.0)
    th = np.linspace(-np.pi / 2, np.pi / 2, 14)[1:-1]
    arc = straight[-1] + [0, 4] + 4 * np.column_stack([np.cos(th), np.sin(th)])
    pts = np.vstack([straight, arc, straight[::-1] + [0, 8]])
    b = np.full(len(pts), 100.0)
    b[60:72] = 70.0
    desc = cbocd_descriptor(pts, b)
    assert np.all(desc[61:71] == 5)


def test_postprocess_steps():
    m = np.zeros(60, dtype=bool)
    m[5:10] = True
    m[12:16] = True  # gap 2 -> joined (short gap)
    m[30:32] = True  # isolated run of 2 -> dropped
    m[40:45] = True  # gap to [12:16] is 24 -> stays separate
    m[52:57] = True  # gap 7 to [40:45] -> joined in the last step
    out = postprocess_ope(m, join_short_gap=3, min_run=4, join_long_gap=10)
    expected = np.zeros(60, dtype=bool)
    expected[5:16] = True
    expected[40:57] = True
    assert np.array_equal(out, expected)


def test_postprocess_short_runs_joined_before_dropping():
    m = np.zeros(30, dtype=bool)
    m[10:12] = True
    m[13:15] = True  # two runs of 2 with a gap of 1: joined to 5, survives min_run=4
    out = postprocess_ope(m, join_short_gap=1, min_run=4, join_long_gap=0)
    assert out[10:15].all() and out.sum() == 5


def test_postprocess_keeps_ends_open():
    m = np.zeros(20, dtype=bool)
    m[3:8] = True
    out = postprocess_ope(m, join_short_gap=5, min_run=2, join_long_gap=50)
    assert np.array_equal(out, m)


# ------------------------------------------------- lengths in px, robust trend
def u_turn(spacing_px: float, radius_px: float = 6.0) -> tuple[np.ndarray, int, int]:
    """Straight 40 px, a U-turn, straight back: (N, 2) and the index range of the arc."""
    n_line = int(round(40 / spacing_px))
    straight = line(n_line, angle_deg=0.0, spacing=spacing_px)
    n_arc = int(round(np.pi * radius_px / spacing_px))
    th = np.linspace(-np.pi / 2, np.pi / 2, n_arc + 2)[1:-1]
    arc = straight[-1] + [0, radius_px] + radius_px * np.column_stack([np.cos(th), np.sin(th)])
    back = straight[::-1] + [0, 2 * radius_px]
    return np.vstack([straight, arc, back]), n_line, n_line + n_arc


@pytest.mark.parametrize("spacing", [0.25, 0.5, 1.0])
def test_curvature_ope_is_the_same_stretch_at_any_spacing(spacing):
    pts, a0, a1 = u_turn(spacing)
    parts = cbocd_parts(pts, np.full(len(pts), 80.0))
    assert parts.spacing_px == pytest.approx(spacing, rel=0.02)
    s = np.arange(len(pts)) * spacing  # arc length (px)
    flagged = s[parts.curvature]
    # the turn (arc length 40 .. 40 + pi * 6 px) is flagged, +- the support half-width
    assert parts.curvature[a0:a1].all()
    assert flagged.min() > 40 - BETA_PX - 1 and flagged.max() < s[a1] + BETA_PX + 1
    assert not parts.brightness.any()


def test_gentle_arc_is_not_curvature_ope_at_fine_spacing():
    th = np.linspace(0, np.pi / 2, 630)  # radius 100 px at 0.25 px spacing
    pts = 100 * np.column_stack([np.cos(th), np.sin(th)])
    assert not cbocd_parts(pts, np.full(len(pts), 80.0)).curvature.any()


def test_px_to_points_and_spacing():
    assert trace_spacing_px(line(11, spacing=0.5)) == pytest.approx(0.5)
    assert px_to_points(10.0, 0.5) == 20
    assert px_to_points(0.1, 0.5, 1) == 1


def test_dark_end_needs_the_robust_trend():
    # a trace whose last 4 px run along the ray: very dark there (more iodine per pixel)
    n = 400  # 0.5 px spacing
    b = np.linspace(100.0, 110.0, n) + np.random.default_rng(3).normal(0, 0.5, n)
    b[-8:] -= 40.0
    paper = brightness_ope(b, trend="ends")
    robust = brightness_ope(b)
    assert not paper[-8:].any()  # InLast is dark: the paper's line hides the OPE
    assert robust[-8:].all() and robust[:-10].mean() < 0.05
    with pytest.raises(ValueError, match="trend"):
        brightness_ope(b, trend="median")
