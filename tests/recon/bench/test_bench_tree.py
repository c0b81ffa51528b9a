"""`bench reconstruct --suite tree`: its keys and one case against the truth."""

from __future__ import annotations

import numpy as np
import pytest
from support import run_cli

from recon.bench.common import pose_error
from recon.bench.tree import (
    STENOSIS_PCT_RANGE,
    _scale_free_tree_mm,
    format_tree,
    run_tree,
    tree_jobs,
    true_bifurcation,
)
from recon.synth.chains import CHAINS
from recon.synth.tree_case import make_tree_case

KEYS = {"cases", "mld_err_mean_mm", "mld_err_sd_mm", "ref_diam_err_mean_mm",
        "bifurcation_angle_err_mean_deg", "bifurcation_angle_err_sd_deg",
        "pose_better_than_header", "pose_better_than_header_scale_free",
        "watertight_single_component", "failed"}


def test_one_tree_case_gives_every_key():
    result = run_tree(1, 0, "tree")
    assert KEYS <= set(result)
    assert result["cases"] == 1 and result["failed"] == []
    row = result["rows"][0]
    assert len(row["segments"]) >= 2 and len(row["bifurcations"]) >= 1
    assert abs(result["mld_err_mean_mm"]) < 0.2
    assert abs(result["bifurcation_angle_err_mean_deg"]) < 5.0
    assert result["watertight_single_component"] == 1.0
    assert max(b["gap_mm"] for b in row["bifurcations"]) <= 0.1
    for bif in row["bifurcations"]:
        assert len(bif["medina_true"].split(",")) == 3
        assert 0.0 <= bif["join_turn_true_deg"] < 30.0  # the phantom's branches are smooth
    assert 0.0 <= result["medina_agreement"] <= 1.0
    assert "Tree suite (tree): 1 cases" in format_tree(result)


def test_the_tree_suite_is_for_bench_reconstruct_only():
    proc = run_cli("bench", "centerline", "--suite", "tree")
    assert proc.returncode == 2
    assert proc.stderr.strip() == "coronary3d: error: bench centerline has no --suite tree " \
                                  "(reconstruct has)"


def test_tree_cases_alternate_table1_and_random_pairs_and_the_varied_one_cycles_the_chains():
    jobs = tree_jobs(12, 0, "tree-varied")
    names = [p if isinstance(p, str) else p.name for p, *_ in jobs]
    assert names[0::2] == ["data1", "data2", "data3", "static", "data1", "data2"]
    assert all(name.startswith("random-") for name in names[1::2])
    chains = [job[3] for job in jobs]
    assert set(chains) == set(CHAINS) and chains[0::2] == chains[1::2]
    severity = [job[4] for job in jobs]
    assert all(STENOSIS_PCT_RANGE[0] <= p <= STENOSIS_PCT_RANGE[1] for p in severity)
    assert len(set(severity)) == len(severity)
    assert [job[3] for job in tree_jobs(4, 0, "tree")] == [None] * 4
    with pytest.raises(ValueError, match="unknown tree suite"):
        tree_jobs(1, 0, "forest")


def test_the_true_bifurcation_qca_finds_the_phantoms_ostial_lesion():
    tc = make_tree_case("data1", 0, "ostium", stenosis_pct=60.0, render=False)
    qca = [true_bifurcation(tc, j) for j in range(1, len(tc.seeds.segments))]
    side = sorted(q.side_branch.diameter_stenosis_pct for q in qca)
    assert len(side) >= 2
    assert side[-1] == pytest.approx(60.0, abs=0.1)  # the ostial lesion as drawn
    assert all(abs(x) < 0.5 for x in side[:-1])  # the healthy branches
    assert sorted(q.medina for q in qca)[-1] == "0,0,1"


def test_the_trees_3d_error_is_blind_to_the_unobservable_baseline_length():
    """The tree's scale-free 3D error (the observable part of B's pose): zero at B's true
    pose and after a pure shift of B's rig along the baseline, which moves the rig by 20 mm
    (the pose displacement sees it; two views cannot); a rotation of B's rig shows."""
    tc = make_tree_case("data1", 0, "ostium", stenosis_pct=60.0, render=False)
    case, X = tc.case, tc.case.truth.segment_X_world
    true_b = case.view_b_true
    assert _scale_free_tree_mm(X, case, true_b) < 1e-6
    baseline = true_b.source_world - case.view_a.source_world
    along = true_b.with_correction(np.zeros(3), 20.0 * baseline / np.linalg.norm(baseline))
    assert _scale_free_tree_mm(X, case, along) < 1e-3
    assert pose_error(along, true_b, X)[1] > 19.0
    turned = true_b.with_correction(np.deg2rad([0.0, 0.0, 1.0]), np.zeros(3))
    assert _scale_free_tree_mm(X, case, turned) > 0.1
