"""recon.tree: a phantom tree reconstructed in one job, against its truth."""

from __future__ import annotations

import json

import numpy as np
import pytest
from support import run_cli
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

from recon.bench.common import case_angiograms
from recon.bench.tree import _branch_truth
from recon.correspond.triangulation import point_polyline_distance
from recon.io.outputs import outputs_as_bytes
from recon.io.seeds_file import save_seeds
from recon.lumen.bifurcation import bifurcation_angles_deg, nearest_on_polyline
from recon.pipeline import reconstruct_pair
from recon.synth import make_phantom
from recon.synth.tree_case import make_tree_case, tree_seeds
from recon.tree import reconstruct_tree


@pytest.fixture(scope="module")
def tree_case():
    tc = make_tree_case("data1", 0, "both")
    assert len(tc.seeds.segments) >= 3  # the main and at least two branches
    a, b = case_angiograms(tc.case)
    return tc, reconstruct_tree(a, b, tc.seeds)


def test_branches_meet_at_their_bifurcations_and_the_angles_match_the_truth(tree_case):
    tc, rec = tree_case
    truth = tc.case.truth
    assert len(rec.bifurcations) == len(tc.seeds.segments) - 1
    main_X, main_r = truth.vessels[0]
    for bq in rec.bifurcations:
        j = tc.seeds.segment_index(bq.branch)
        start = rec.branches[j].centerline_3d.X_world[0]
        foot, _, _ = nearest_on_polyline(rec.branches[0].centerline_3d.X_world, start)
        assert np.linalg.norm(start - foot) <= 0.1  # no gap
        assert bq.gap_mm <= 0.1
        true_angle, _, _ = bifurcation_angles_deg(main_X, main_r, truth.vessels[tc.vessels[j]][0])
        assert bq.bifurcation_angle_deg == pytest.approx(true_angle, abs=5.0)
        assert bq.medina in {f"{p},{d},{s}" for p in "01" for d in "01" for s in "01"}


def test_lesions_are_measured_on_every_branch_and_view_b_beats_its_header(tree_case):
    tc, rec = tree_case
    lesions = 0
    for j, branch in enumerate(rec.branches):
        mld_true, ref_true = _branch_truth(tc, j)
        if mld_true < 0.75 * ref_true:  # the main's and the narrowed ostium's
            lesions += 1
            m = branch.measurements
            if j > 0 and not m.has_lesion:  # inside the ostium zone: listed, not confirmed
                (m,) = [n for n in branch.lesions.unsupported if n.zone == "ostium"]
            assert m.mld_mm == pytest.approx(mld_true, abs=0.2)
            assert m.reference_diameter_mm == pytest.approx(ref_true, abs=0.3)
        # every branch's 3D centerline lies on its vessel in both views
        assert branch.metrics["a"]["rms_px"] < 2.0 and branch.metrics["b"]["rms_px"] < 2.0
    assert lesions >= 2
    from recon.bench.common import pose_error

    X = tc.case.truth.segment_X_world
    assert (pose_error(rec.first.view_b, tc.case.view_b_true, X)[1]
            < pose_error(tc.case.view_b_nominal, tc.case.view_b_true, X)[1])


def test_the_tree_mesh_is_one_watertight_union(tree_case):
    _, rec = tree_case
    mesh = rec.tree_surface.mesh
    assert rec.tree_surface.components == 1
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    assert len(mesh.split(only_watertight=False)) == 1
    # the union holds less than the branches counted apart (they overlap at each bifurcation)
    assert mesh.volume < sum(b.surface.mesh.volume for b in rec.branches)
    assert mesh.volume > rec.branches[0].surface.mesh.volume


def test_outputs_carry_every_branch(tree_case, tmp_path):
    tc, rec = tree_case
    files = outputs_as_bytes(rec)
    report = json.loads(files["report.json"])
    single = set(rec.first.report())
    assert single <= set(report)  # today's keys, for the first segment
    assert len(report["branches"]) == len(tc.seeds.segments)
    assert set(report["branches"][1]) >= single
    assert report["measurements"] == {**rec.first.measurements.to_dict(),
                                      "ffr": round(rec.first.ffr.distal, 4)}
    # every branch's FFR block and value, solved over the tree (recon.lumen.ffr)
    for entry, branch in zip(report["branches"], rec.branches, strict=True):
        assert entry["measurements"]["ffr"] == entry["ffr"]["distal"] == round(branch.ffr.distal, 4)
        assert len(entry["ffr"]["s_mm"]) == len(entry["ffr"]["ffr"]) == len(branch.profile.s_mm)
        parent = tc.seeds.segments[branch.options.segment].parent
        if parent is not None:  # a branch's pullback starts at its parent's pressure there
            up = rec.branches[tc.seeds.segment_index(parent)]
            join = nearest_on_polyline(up.centerline_3d.X_world, branch.centerline_3d.X_world[0])
            assert branch.ffr.ffr[0] == pytest.approx(np.interp(join[1], up.ffr.s_mm, up.ffr.ffr),
                                                      abs=1e-3)
    assert report["tree"]["mesh"]["components"] == 1
    assert {"bifurcation_angle_deg", "medina", "side_branch"} <= set(report["bifurcations"][0])
    lines = files["centerline.csv"].decode().splitlines()
    assert lines[0].split(",")[-1] == "branch"
    branch = np.array([int(line.rsplit(",", 1)[1]) for line in lines[1:]])
    counts = [len(b.centerline_3d.s_mm) for b in rec.branches]
    assert np.array_equal(branch, np.repeat(np.arange(len(counts)), counts))
    (tmp_path / "c.vtp").write_bytes(files["centerline.vtp"])
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(tmp_path / "c.vtp"))
    reader.Update()
    poly = reader.GetOutput()
    assert poly.GetNumberOfLines() == len(counts)
    assert np.array_equal(vtk_to_numpy(poly.GetPointData().GetArray("BranchId")), branch)
    assert poly.GetPointData().GetArray("Radius") is not None


def test_a_tree_of_one_segment_is_the_one_segment_reconstruction():
    case = make_phantom("data2", 3)
    a, b = case_angiograms(case)
    tree = reconstruct_tree(a, b, case.seeds)
    single = reconstruct_pair(a, b, case.seeds)
    np.testing.assert_array_equal(tree.first.centerline_3d.X_world, single.centerline_3d.X_world)
    assert tree.first.measurements == single.measurements
    assert tree.bifurcations == ()


def test_reconstruct_on_the_command_line_does_every_segment_or_the_one_named(tmp_path):
    case = make_phantom("static", 7, render=False)  # the demo case
    seeds, _, _ = tree_seeds(np.random.default_rng(1), case)
    path = tmp_path / "tree.json"
    save_seeds(seeds, path)
    out = tmp_path / "out"
    proc = run_cli("reconstruct", "--demo", "--seeds", str(path), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    report = json.loads((out / "report.json").read_text())
    assert [b["inputs"]["segment"] for b in report["branches"]] == ["main", "branch 1"]
    assert report["bifurcations"][0]["gap_mm"] <= 0.1
    assert "branch 1: length" in proc.stderr and "Medina" in proc.stderr
    proc = run_cli("reconstruct", "--demo", "--seeds", str(path), "--segment", "LCX",
                   "--out", str(tmp_path / "x"))
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "no segment 'LCX'" in proc.stderr
    assert not (tmp_path / "x").exists()


def test_each_branchs_best_view_keeps_the_other_branches_off_it(tree_case):
    """A branch's recommended view is chosen with the tree's other branches as vessels it
    must not overlap: its overlap map counts them (it differs from the map of the branch
    alone, which sees only the branch crossing itself), and its best angle is at least as
    good as the branch-alone choice by that measure (foreshortening + overlap)."""
    from recon.pose.optimal_view import optimal_view

    _, tree = tree_case
    for rec in tree.branches:
        c = rec.centerline_3d
        radius = rec.profile.smooth_radius_at(c.s_mm)
        alone = optimal_view(c.X_world, radius, rec.view_a)
        chosen = rec.optimal_view
        assert chosen is not None
        assert np.any(chosen.overlap_map_pct > alone.overlap_map_pct + 1e-9)
        score = chosen.foreshortening_map_pct + chosen.overlap_map_pct
        alphas, betas = list(chosen.alpha_grid_deg), list(chosen.beta_grid_deg)
        best, other = ((betas.index(v.angles_deg[1]), alphas.index(v.angles_deg[0]))
                       for v in (chosen, alone))
        assert score[best] <= score[other] + 1e-9
        assert chosen.overlap_pct == pytest.approx(chosen.overlap_map_pct[best])


@pytest.fixture(scope="module")
def small_tree():
    """The demo phantom with one clicked branch: a two-segment tree, quick to reconstruct."""
    case = make_phantom("static", 7)
    seeds, _, _ = tree_seeds(np.random.default_rng(1), case)
    assert len(seeds.segments) == 2
    return case_angiograms(case), seeds


@pytest.mark.parametrize("mode", ["header", "supported", "curves"])
def test_the_tree_calibrates_by_the_rule_a_single_segment_uses(small_tree, mode):
    """``ReconstructionOptions.calibration`` reaches the tree: the tree's view B is what
    :func:`recon.pipeline.calibrate_view_b` makes of the tree-wide features under that
    rule, and "header" leaves B at its header pose."""
    from recon.pipeline import ReconstructionOptions, calibrate_view_b
    from recon.tree import _tree_features

    (a, b), seeds = small_tree
    options = ReconstructionOptions(calibration=mode)
    tree = reconstruct_tree(a, b, seeds, options)
    traced = [(rec.centerline_a, rec.centerline_b) for rec in tree.branches]
    feat_a, feat_b = _tree_features(seeds, traced)
    expected = calibrate_view_b(a.geometry, b.geometry, feat_a, feat_b, options,
                                (traced[0][0].points_px, traced[0][1].points_px))
    assert tree.calibration.correction == expected.correction
    np.testing.assert_allclose(tree.first.view_b.source_world, expected.view_b.source_world,
                               atol=1e-9)
    if mode == "header":
        assert tree.calibration.correction == "header"
        np.testing.assert_allclose(tree.first.view_b.source_world, b.geometry.source_world,
                                   atol=1e-9)
    if mode == "curves":
        assert tree.calibration.correction == "curves"
    assert all(rec.view_b is tree.first.view_b for rec in tree.branches)
    assert all(rec.calibration is tree.calibration for rec in tree.branches)
    assert tree.first.intervals is not None  # the rule's pose posterior gives intervals
    # a joined branch is measured from its carina, and so are its intervals' draws
    for rec in tree.branches[1:]:
        assert rec.intervals is not None
        for key, (lo, hi) in rec.intervals.ci95.items():
            assert lo <= rec.measurements.to_dict()[key] <= hi, key


def test_an_unknown_calibration_rule_is_refused_before_tracing(small_tree, monkeypatch):
    import recon.tree
    from recon.pipeline import PipelineError, ReconstructionOptions

    def no_tracing(*args, **kwargs):
        raise AssertionError("traced before the options were checked")

    monkeypatch.setattr(recon.tree, "_trace_both", no_tracing)
    (a, b), seeds = small_tree
    with pytest.raises(PipelineError, match="unknown calibration 'sideways'"):
        reconstruct_tree(a, b, seeds, ReconstructionOptions(calibration="sideways"))


def test_each_branch_gets_its_best_view_computed_once(small_tree, monkeypatch):
    """The tree chooses every branch's view among the others, so reconstruct_pair's
    own choice (the branch alone) is skipped: one optimal_view call per branch."""
    import recon.pipeline
    import recon.tree

    calls = []
    real = recon.tree.optimal_view

    def counting(*args, **kwargs):
        calls.append(kwargs.get("others"))
        return real(*args, **kwargs)

    monkeypatch.setattr(recon.tree, "optimal_view", counting)
    monkeypatch.setattr(recon.pipeline, "optimal_view", counting)
    (a, b), seeds = small_tree
    tree = reconstruct_tree(a, b, seeds)
    assert len(calls) == len(seeds.segments)
    assert all(others is not None and len(others) == len(seeds.segments) - 1 for others in calls)
    assert all(rec.optimal_view is not None for rec in tree.branches)


def test_a_trace_is_untrusted_where_another_segment_overlaps_its_lumen_in_that_view():
    """Lumens that overlap in one view (centres closer than half the radii's sum) lower
    that view's reliability there and only there; the other view stays as traced."""
    from recon.tree import TREE_OVERLAP_RELIABILITY, _mark_tree_overlaps
    from recon.types import Centerline2D

    def trace(points, radius):
        n = len(points)
        return Centerline2D(points_px=np.asarray(points, dtype=float),
                            radius_px=np.full(n, radius), brightness=np.ones(n))

    x = np.arange(0.0, 100.0)
    main_a = trace(np.column_stack([x, np.full(100, 50.0)]), 4.0)
    main_b = trace(np.column_stack([x, np.full(100, 50.0)]), 4.0)
    # in A the branch crosses the main at x = 40 (vertical); in B it stays 20 px away
    branch_a = trace(np.column_stack([np.full(60, 40.0), np.arange(20.0, 80.0)]), 3.0)
    branch_b = trace(np.column_stack([np.arange(20.0, 80.0), np.full(60, 70.0)]), 3.0)
    marked = _mark_tree_overlaps([(main_a, main_b), (branch_a, branch_b)])
    low = marked[0][0].reliability <= TREE_OVERLAP_RELIABILITY
    np.testing.assert_array_equal(np.flatnonzero(low), np.arange(37, 44))  # |x - 40| < 3.5
    low_branch = marked[1][0].reliability <= TREE_OVERLAP_RELIABILITY
    np.testing.assert_array_equal(np.flatnonzero(low_branch), np.arange(27, 34))  # |y - 50| < 3.5
    assert np.all(marked[0][1].reliability == 1.0) and np.all(marked[1][1].reliability == 1.0)


def test_a_branch_origin_traced_along_its_parent_is_redrawn_from_the_clear_view():
    """A branch leaving its parent at 25 deg in 3D; view B's trace of it runs 6 mm along
    the parent's centre before it crosses over (as a trace through merged lumens does),
    view A's follows the branch. The redrawn B stretch lies on the branch's true
    projection (within 1 px), far closer than the trace it replaces; A is unchanged."""
    from recon.tree import TREE_OVERLAP_RELIABILITY, _origin_from_the_clear_view
    from recon.types import Centerline2D

    case = make_phantom("static", 7, render=False)
    view_a, view_b = case.view_a, case.view_b_true
    centre = np.asarray(case.truth.segment_X_world[len(case.truth.segment_X_world) // 2])
    u = np.array([1.0, 0.0, 0.0])
    w = np.array([np.cos(np.radians(25.0)), np.sin(np.radians(25.0)), 0.0])
    s = np.arange(0.0, 30.0, 0.1)[:, None]
    parent_X = centre + (s - 10.0) * u
    branch_X = centre + s * w

    def trace(view, X, radius_mm):
        p = view.project(X)
        r = np.full(len(p), radius_mm / view.pixel_mm_at_isocenter)
        return Centerline2D(points_px=p, radius_px=r, brightness=np.ones(len(p)))

    parent = (trace(view_a, parent_X, 1.5), trace(view_b, parent_X, 1.5))
    true_b = view_b.project(branch_X)
    # B's trace: along the parent's centre for 6 mm, then a straight jump onto the branch
    along = centre + s[s[:, 0] <= 6.0] * u
    rejoin = np.flatnonzero(s[:, 0] >= 9.0)[0]
    bad = np.vstack([along, branch_X[rejoin:]])
    branch = (trace(view_a, branch_X, 1.0), trace(view_b, bad, 1.0))
    (a_new, b_new), mismatch = _origin_from_the_clear_view(branch, parent, view_a, view_b)
    assert a_new is branch[0] and mismatch is None
    changed = np.flatnonzero(np.any(b_new.points_px != branch[1].points_px, axis=1))
    assert changed.size > 10
    before = np.max(point_polyline_distance(branch[1].points_px[changed], true_b))
    after = np.max(point_polyline_distance(b_new.points_px[changed], true_b))
    assert before > 3.0 and after < 1.0, (before, after)
    assert np.all(b_new.reliability[changed] <= TREE_OVERLAP_RELIABILITY)

    # B's trace instead follows the parent for 8 mm and then another vessel (3 mm off
    # the branch, below its plane) before it reaches the branch: where it leaves the
    # parent, its epipolar line misses A's trace of the branch. Nothing is redrawn; the
    # mismatch names view B.
    off = np.array([0.0, 0.0, -3.0])
    detour_X = np.vstack([centre + s[s[:, 0] <= 8.0] * u,
                          centre + 8.0 * u + off + s[s[:, 0] <= 12.0] * w,
                          branch_X[np.flatnonzero(s[:, 0] >= 20.0)[0]:]])
    detour = (trace(view_a, branch_X, 1.0), trace(view_b, detour_X, 1.0))
    (a_same, b_same), mismatch = _origin_from_the_clear_view(detour, parent, view_a, view_b)
    assert a_same is detour[0] and b_same is detour[1]
    assert mismatch is not None and mismatch.view == "B" and mismatch.miss_px > 2.0
    line = mismatch.warning("bif 1", "D1", "LAD")
    assert line.startswith("bif 1: in view B the trace of D1 runs ")
    assert line.endswith("add a waypoint on D1 just past its origin in view B")
    assert mismatch.form("bif {1}").format(parent="LAD", branch="D1") == line.replace(
        "bif 1", "bif {1}")

    # both views' traces stay on the parent's centre line: the origin is seen in neither
    from recon.tree import OriginUnseen

    inside = centre + s[s[:, 0] <= 8.0] * u
    merged = (trace(view_a, inside, 1.0), trace(view_b, inside, 1.0))
    kept, unseen = _origin_from_the_clear_view(merged, parent, view_a, view_b)
    assert kept is merged and isinstance(unseen, OriginUnseen)
    assert unseen.warning("bif 1", "D1", "LAD").startswith(
        "bif 1: D1 does not part from LAD's shadow in either view")


def test_a_refused_branch_trace_names_its_segment_view_and_place():
    """In a tree a refused trace names its segment and stays a TraceError with its view
    and place (what the viewer rings)."""
    from dataclasses import replace

    from recon.io import demo_paths, load_angiogram, load_seeds
    from recon.seeds import Seeds
    from recon.trace.trace_error import TraceError

    demo = demo_paths()
    a, b = load_angiogram(demo["a"]), load_angiogram(demo["b"])
    seeds = load_seeds(demo["seeds"])
    seg = seeds.segments[0]
    p = seg.a_px  # a second segment whose distal end in A is clicked second
    bad = replace(seg, name="again", a_px=(p[0], p[-1], p[1], p[2]))
    with pytest.raises(TraceError, match=r"^segment 'again': view A: the trace doubles back "
                                         r"at click 2 ") as info:
        reconstruct_tree(a, b, Seeds(segments=(seg, bad), features=seeds.features))
    assert info.value.view == "A"
    np.testing.assert_allclose(info.value.near_px, p[-1], atol=3.0)
