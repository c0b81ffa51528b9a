"""recon.lumen.bifurcation: a branch joined to its parent, bifurcation QCA, on exact geometry."""

from __future__ import annotations

import numpy as np
import pytest

from recon.lumen.bifurcation import (
    MAX_JOIN_TURN_DEG,
    Junction,
    bifurcation_angles_deg,
    bifurcation_qca,
    carina_s_mm,
    nearest_on_polyline,
    origin_warning,
    sharpest_turn_deg,
)
from recon.types import Centerline3D, arclength


def _line(start, direction, length_mm: float, step: float = 0.1) -> np.ndarray:
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    return np.asarray(start, float) + np.arange(0.0, length_mm + 1e-9, step)[:, None] * d


def _y(theta_deg: float, r_parent: float = 1.5):
    """A straight parent along x (60 mm) and a branch leaving it at x = 30 at theta."""
    parent = _line([0, 0, 0], [1, 0, 0], 60.0)
    t = np.deg2rad(theta_deg)
    branch = _line([30, 0, 0], [np.cos(t), np.sin(t), 0.0], 30.0)
    return parent, np.full(len(parent), r_parent), branch


@pytest.mark.parametrize("theta", [30.0, 55.0, 80.0])
def test_angles_of_a_straight_y_are_the_construction_angles(theta):
    parent, r, branch = _y(theta)
    bif, prox, info = bifurcation_angles_deg(parent, r, branch)
    assert bif == pytest.approx(theta, abs=0.05)
    assert prox == pytest.approx(180.0 - theta, abs=0.05)
    # the branch leaves the lumen where its distance to the axis reaches the radius
    assert info["carina_s_mm"] == pytest.approx(1.5 / np.sin(np.deg2rad(theta)), abs=0.11)
    assert info["junction_s_mm"] == pytest.approx(30.0, abs=1e-9)


@pytest.mark.parametrize("off_mm", [0.1, 0.6, 2.0])
def test_the_join_moves_the_start_onto_the_parent_and_keeps_the_branch_beyond_the_blend(
        off_mm: float):
    """No gap; the branch unchanged beyond the carina or, for a start far off the parent,
    beyond the stretch over which the shift is blended out without turning the branch
    by more than MAX_JOIN_TURN_DEG."""
    parent, r, branch = _y(45.0)
    off = branch + np.array([0.0, 0.0, off_mm])  # triangulated off the parent
    T = np.gradient(off, axis=0)
    T /= np.linalg.norm(T, axis=1)[:, None]
    cl = Centerline3D(X_world=off, s_mm=arclength(off), tangents=T,
                      radius_a_mm=np.ones(len(off)), radius_b_mm=np.ones(len(off)),
                      X_raw_world=off, points_a_px=np.zeros((len(off), 2)),
                      points_b_px=np.zeros((len(off), 2)))
    joined = Junction(parent, r).join(cl)
    foot, _, _ = nearest_on_polyline(parent, joined.X_world[0])
    assert np.linalg.norm(joined.X_world[0] - foot) < 1e-9  # no gap
    blend = max(carina_s_mm(off, parent, r), 1.0,
                np.pi * off_mm / (2.0 * np.tan(np.radians(MAX_JOIN_TURN_DEG))))
    beyond = cl.s_mm >= blend
    np.testing.assert_allclose(joined.X_world[beyond], off[beyond], atol=1e-12)
    assert np.all(np.linalg.norm(joined.tangents, axis=1) == pytest.approx(1.0))
    assert sharpest_turn_deg(joined.X_world, 30.0, chord_mm=0.2) < MAX_JOIN_TURN_DEG + 0.5


def test_qca_finds_the_lesions_and_the_medina_class():
    parent, r, branch = _y(50.0, r_parent=1.5)
    s_p, s_b = arclength(parent), arclength(branch)
    ref_p, ref_b = np.full(len(s_p), 3.0), np.full(len(s_b), 2.0)
    # a 60 % lesion in the distal main just beyond the carina, a 30 % one at the side ostium
    d_p = ref_p * (1 - 0.6 * np.exp(-(((s_p - 35.0) / 1.5) ** 2)))
    d_b = ref_b * (1 - 0.3 * np.exp(-(((s_b - 5.0) / 1.5) ** 2)))
    q = bifurcation_qca("LAD/D1", "LAD", "D1", parent, (s_p, d_p, ref_p), branch,
                        (s_b, d_b, ref_b), join_shift_mm=0.2)
    assert q.medina == "0,1,0"
    assert q.distal_main.mld_mm == pytest.approx(1.2, abs=0.01)
    assert q.distal_main.diameter_stenosis_pct == pytest.approx(60.0, abs=0.5)
    assert q.side_branch.diameter_stenosis_pct == pytest.approx(30.0, abs=0.5)
    assert q.proximal_main.reference_diameter_mm == pytest.approx(3.0)
    assert q.proximal_main.end_s_mm == pytest.approx(30.0 - 1.5 * (1 - 0.0), abs=0.2)
    assert q.bifurcation_angle_deg == pytest.approx(50.0, abs=0.05)
    assert q.gap_mm < 1e-9 and q.join_shift_mm == 0.2
    assert set(q.to_dict()["side_branch"]) >= {"mld_mm", "reference_diameter_mm"}


def test_a_branch_that_stays_inside_its_parent_long_before_a_steep_turn_is_flagged():
    """A 60 deg branch clears a 1.5 mm lumen after 1.5 / sin(60) = 1.7 mm of its arc: a
    branch traced 6 mm along its parent first (then turning off at 60 deg) is flagged,
    the straight one is not; a shallow branch (15 deg: 5.8 mm) may stay that long."""
    parent, r, branch = _y(60.0, r_parent=1.5)
    s_p, s_b = arclength(parent), arclength(branch)
    profiles = ((s_p, np.full(len(s_p), 3.0), np.full(len(s_p), 3.0)),
                (s_b, np.full(len(s_b), 2.0), np.full(len(s_b), 2.0)))
    straight = bifurcation_qca("b1", "LAD", "D1", parent, profiles[0], branch, profiles[1], 0.0)
    assert straight.origin_warning is None
    along = _line([30, 0, 0], [1, 0, 0], 6.0)  # 6 mm inside the parent, then off at 60 deg
    t = np.deg2rad(60.0)
    detour = np.vstack([along, along[-1] + _line([0, 0, 0], [np.cos(t), np.sin(t), 0], 25.0)[1:]])
    s_d = arclength(detour)
    q = bifurcation_qca("b1", "LAD", "D1", parent, profiles[0], detour,
                        (s_d, np.full(len(s_d), 2.0), np.full(len(s_d), 2.0)), 0.0)
    assert q.carina_s_mm > 6.0
    assert q.origin_warning is not None and q.origin_warning.startswith("b1: D1 stays")
    assert "add a waypoint on D1 just past its origin" in q.origin_warning
    assert q.to_dict()["origin_warning"] == q.origin_warning
    assert "origin_form" not in q.to_dict()
    assert origin_warning("b1", "LAD", "D1", 6.0, 1.5, 15.0) is None
    # a renamed segment is renamed in the warning too, and only where it is named
    diag = q.renamed("D1", "Diag {1}")
    assert (diag.branch, diag.parent) == ("Diag {1}", "LAD")
    assert diag.origin_warning == q.origin_warning.replace("D1", "Diag {1}")
    main = diag.renamed("LAD", "a")  # a name that is also a word of the sentence
    assert main.parent == "a" and main.origin_warning.count("a's lumen") == 1
    assert main.origin_warning.replace("inside a's", "inside LAD's").replace(
        "follows a first", "follows LAD first") == diag.origin_warning
    assert q.renamed("LCx", "OM1") == q


def test_sharpest_turn_is_the_corner_of_a_polyline_and_the_chord_angle_of_an_arc():
    corner = np.deg2rad(30.0)
    leg = np.linspace(0.0, 5.0, 51)[:, None]
    first = leg * [1.0, 0.0, 0.0]
    second = first[-1] + leg[1:] * [np.cos(corner), np.sin(corner), 0.0]
    bent = np.vstack([first, second])  # a 30 degree corner at arc length 5 mm
    assert sharpest_turn_deg(bent, 10.0) == pytest.approx(30.0, abs=1e-6)
    assert sharpest_turn_deg(bent, 4.9) == pytest.approx(0.0, abs=1e-6)  # before the corner
    assert sharpest_turn_deg(first, 5.0) == pytest.approx(0.0, abs=1e-6)
    radius_mm = 10.0
    t = np.linspace(0.0, 1.5, 400)
    arc = radius_mm * np.column_stack([np.cos(t), np.sin(t), np.zeros_like(t)])
    # successive 1 mm chords of a 10 mm circle turn by 2 asin(0.05) each
    assert sharpest_turn_deg(arc, 12.0) == pytest.approx(np.degrees(2 * np.arcsin(0.05)),
                                                         rel=1e-3)
