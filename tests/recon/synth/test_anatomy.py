"""Harder anatomy: each variant does what it says; the truth stays exact (synth/anatomy.py)."""

from dataclasses import replace

import numpy as np
import pytest

from recon.synth import ANATOMIES, make_phantom
from recon.synth.anatomy import _self_intersects, loop_crossing_views
from recon.synth.render import vessel_attenuations
from recon.synth.tree import MAIN_RADIUS_PROXIMAL_MM, SAMPLE_STEP_MM, draw_tree, truth_from_tree
from recon.types import arclength


def first_tree(seed: int, **flags):
    rng = np.random.default_rng(seed)
    for _ in range(500):
        tree = draw_tree(rng, **flags)
        if tree is not None:
            return tree
    raise AssertionError("no tree drawn")


def test_the_variants_are_named():
    assert set(ANATOMIES) == {"plain", "branch-stenosis", "crossing", "loop", "faint",
                              "eccentric"}


def test_a_polyline_crossing_itself_is_found():
    t = np.linspace(0, 2 * np.pi, 60)
    figure_eight = np.column_stack([np.sin(t), np.sin(t) * np.cos(t)])
    assert _self_intersects(figure_eight)
    assert not _self_intersects(np.column_stack([t, np.sin(t)]))


@pytest.mark.parametrize("seed", [1, 2])
def test_the_loop_crosses_itself_in_projection_but_not_in_3d(seed):
    case = make_phantom("data1", seed, anatomy="loop", render=False)
    info = case.anatomy_info
    lo, hi = info["loop_s_mm"]
    assert 20.0 < hi - lo < 60.0
    assert info["loop_crossing_views"]  # at least one view sees the loop cross itself
    views = {"A": case.view_a, "B": case.view_b_true}
    main_X = case.truth.vessels[0][0]
    for name in info["loop_crossing_views"]:
        assert loop_crossing_views(main_X, (lo, hi), [views[name]]) == (0,)
    # The loop lies inside the segment, clear of the lesion.
    start = case.truth.segment_start_s_mm
    s_lesion = start + case.truth.stenosis_s_mm
    half = case.truth.stenosis_length_mm / 2
    assert start < lo and hi < start + case.truth.segment_length_mm
    assert s_lesion + half < lo or s_lesion - half > hi
    # In 3D the two passes keep their lumens apart.
    s = np.arange(len(main_X)) * SAMPLE_STEP_MM
    idx = np.flatnonzero((s >= lo) & (s <= hi))
    d = np.linalg.norm(main_X[idx, None] - main_X[None, idx], axis=2)
    apart = np.abs(s[idx, None] - s[None, idx]) > 6.0 + 2 * MAIN_RADIUS_PROXIMAL_MM[1]
    r = case.truth.vessels[0][1][idx]
    assert np.all(d[apart] >= (r[:, None] + r[None, :])[apart])


def test_the_eccentric_stenosis_moves_the_lumen_centre():
    tree = first_tree(3, eccentric=True)
    fraction, _ = tree.eccentric
    ecc, _ = truth_from_tree(tree, 50.0, np.zeros(3), np.zeros(3))
    conc, _ = truth_from_tree(replace(tree, eccentric=None), 50.0, np.zeros(3), np.zeros(3))
    offset = np.linalg.norm(ecc.segment_X_world - conc.segment_X_world, axis=1)
    # At the lesion centre the centre moves by fraction x (reference - lumen radius).
    i = int(np.argmin(conc.segment_radius_mm))
    r_ref = conc.reference_diameter_mm / 2
    assert offset[i] == pytest.approx(fraction * (r_ref - conc.segment_radius_mm[i]), rel=1e-3)
    assert offset.max() > 0.3
    # Outside the lesion nothing moves; radii, MLD and %DS are the concentric ones.
    s = conc.segment_s_mm
    outside = np.abs(s - conc.stenosis_s_mm) > conc.stenosis_length_mm / 2 + 0.1
    assert np.all(offset[outside] < 1e-12)
    assert np.array_equal(ecc.segment_radius_mm, conc.segment_radius_mm)
    assert ecc.mld_mm == conc.mld_mm and ecc.stenosis_diameter_pct == 50.0
    # The truth's arc length is the lumen centre's own.
    assert np.allclose(ecc.segment_s_mm, arclength(ecc.segment_X_world))
    assert ecc.segment_volume_mm3 == pytest.approx(
        np.pi * np.trapezoid(ecc.segment_radius_mm**2, ecc.segment_s_mm))
    # Perpendicular to the axis: the offset direction is normal to the tangent.
    t = np.gradient(conc.segment_X_world, axis=0)
    move = ecc.segment_X_world - conc.segment_X_world
    cos = np.abs(np.sum(t * move, axis=1)) / (np.linalg.norm(t, axis=1) * offset + 1e-12)
    assert np.all(cos[offset > 0.05] < 0.05)


def test_the_branch_stenosis_puts_a_branch_on_the_lesion_shoulder():
    for seed in range(3):
        tree = first_tree(seed, branch_stenosis=True)
        gap = np.min(np.abs(tree.branch_s - tree.sten_s_main)) / tree.sten_len
        assert 0.3 <= gap <= 0.6
        # The branch starts on the main vessel at that arc length.
        k = int(np.argmin(np.abs(tree.branch_s - tree.sten_s_main)))
        i = int(round(tree.branch_s[k] / SAMPLE_STEP_MM))
        assert np.linalg.norm(tree.branches_X[k][0] - tree.main_X[i]) < 1e-3


def test_the_crossing_vessel_lies_over_the_lesion_in_one_view_only():
    for seed in (0, 1, 2):
        case = make_phantom("data3", seed, anatomy="crossing", render=False)
        names = case.truth.vessel_names
        assert "crossing" in names
        X = case.truth.vessels[names.index("crossing")][0]
        i = int(np.argmin(np.abs(case.truth.segment_s_mm - case.truth.stenosis_s_mm)))
        P = case.truth.segment_X_world[i : i + 1]
        views = {"A": case.view_a, "B": case.view_b_true}
        over = case.anatomy_info["crossing_view"]
        other = "B" if over == "A" else "A"

        def gap_px(view, X=X, P=P):
            return float(np.min(np.linalg.norm(view.project(X) - view.project(P), axis=1)))

        assert gap_px(views[over]) < 1.0
        assert gap_px(views[other]) * views[other].pixel_spacing_mm[0] >= 5.0
        # Not touching in 3D: it passes 12-25 mm in front of or behind the lesion.
        assert np.min(np.linalg.norm(X - P, axis=1)) > 10.0
        # Not a branch: no extra bifurcation click.
        assert len(case.seeds.features) == len(case.truth.feature_names) - 2


def test_faint_distal_ends_fade_strongly():
    case = make_phantom("static", 1, anatomy="faint", render=False)
    distal = case.anatomy_info["faint_distal_fraction"]
    assert 0.12 <= distal <= 0.25
    mus = vessel_attenuations(case.truth.vessels, 0.1, distal, 2.0)
    plain = vessel_attenuations(case.truth.vessels, 0.1)
    assert mus[0][-1] == pytest.approx(0.1 * distal)
    assert plain[0][-1] == pytest.approx(0.07)
    half = len(mus[0]) // 2
    assert np.all(mus[0][half:] < plain[0][half:])  # the distal half is fainter
    image = make_phantom("static", 1, anatomy="faint").image_a
    assert image is not None


def test_every_variant_keeps_the_truth_exact():
    for name in ANATOMIES:
        case = make_phantom("data2", 5, anatomy=name, render=False)
        t = case.truth
        assert np.allclose(t.segment_s_mm, arclength(t.segment_X_world), atol=0.01)
        lesion = np.abs(t.segment_s_mm - t.stenosis_s_mm) <= t.stenosis_length_mm / 2 + 0.05
        assert t.mld_mm == pytest.approx(2 * t.segment_radius_mm[lesion].min(), abs=1e-9)
        assert 100 * (1 - t.mld_mm / t.reference_diameter_mm) == pytest.approx(50.0, abs=0.5)
        assert case.anatomy == name
