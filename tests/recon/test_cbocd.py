import numpy as np
import pytest

from recon.cbocd import (
    brightness_ope,
    cbocd_descriptor,
    curvature_ope,
    postprocess_ope,
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
