"""`bench reconstruct --suite tree`: its keys and one case against the truth."""

from __future__ import annotations

from support import run_cli

from recon.bench.reconstruct import format_table, run

KEYS = {"cases", "mld_err_mean_mm", "mld_err_sd_mm", "ref_diam_err_mean_mm",
        "bifurcation_angle_err_mean_deg", "bifurcation_angle_err_sd_deg",
        "pose_better_than_header", "watertight_single_component", "failed"}


def test_one_tree_case_gives_every_key():
    result = run(cases=1, seed=0, suite="tree")
    assert KEYS <= set(result)
    assert result["cases"] == 1 and result["failed"] == []
    row = result["rows"][0]
    assert len(row["segments"]) >= 2 and len(row["bifurcations"]) >= 1
    assert abs(result["mld_err_mean_mm"]) < 0.2
    assert abs(result["bifurcation_angle_err_mean_deg"]) < 5.0
    assert result["watertight_single_component"] == 1.0
    assert max(b["gap_mm"] for b in row["bifurcations"]) <= 0.1
    assert "Tree suite: 1 cases" in format_table(result)


def test_the_tree_suite_is_for_bench_reconstruct_only():
    proc = run_cli("bench", "centerline", "--suite", "tree")
    assert proc.returncode == 2
    assert proc.stderr.strip() == "coronary3d: error: bench centerline has no --suite tree " \
                                  "(reconstruct has)"
