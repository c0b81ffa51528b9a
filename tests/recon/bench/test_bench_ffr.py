"""`coronary3d bench ffr`: the analytic checks, the case draw's stenosis spread, the figures,
one reconstructed case against the true lumen, and the command line."""

from __future__ import annotations

import inspect
import json

import numpy as np
import pytest
from support import run_cli

from recon.bench import ffr as bench
from recon.lumen.ffr import FFRModel
from recon.synth import make_phantom


def test_run_takes_cases_and_seed_then_the_varied_count():
    params = inspect.signature(bench.run).parameters
    assert list(params) == ["cases", "seed", "varied_per_chain"]
    assert params["cases"].default is None and params["seed"].default == 0


def test_the_analytic_checks_pass_within_their_tolerances():
    result = bench.analytic()
    tube, narrowing = result["straight_tube"], result["narrowing"]
    assert tube["pass"] and tube["rel_err"] <= 0.005 and tube["flow_rel_err"] <= 0.005
    assert narrowing["pass"] and narrowing["max_rel_err"] <= 0.01
    assert [r["stenosis_pct"] for r in narrowing["cases"]] == list(bench.NARROWING_PCT)
    ffrs = [r["ffr"] for r in narrowing["cases"]]
    assert ffrs == sorted(ffrs, reverse=True) and ffrs[-1] < 0.5  # severity lowers the FFR


def test_the_analytic_check_would_see_a_wrong_separation_loss():
    # the closed form is the model's own: a model whose Kt differs from the closed form's
    # would miss it (here: the closed form with the other model's Kt, the drop with this)
    right = bench.analytic(FFRModel())
    wrong = bench.analytic(FFRModel(kt=1.0))
    assert right["narrowing"]["cases"][2]["drop_mmhg"] != pytest.approx(
        wrong["narrowing"]["cases"][2]["drop_mmhg"], rel=0.01)


def test_each_case_draws_its_own_stenosis_and_the_suites_hold_lesions_below_the_cutoff():
    pcts = [bench.case_stenosis_pct(5300, k) for k in range(56)]
    assert pcts == [bench.case_stenosis_pct(5300, k) for k in range(56)]  # seeded
    lo, hi = bench.STENOSIS_PCT_RANGE
    assert all(lo <= p <= hi for p in pcts) and np.ptp(pcts) > 0.6 * (hi - lo)
    # the regular suite's truth (no rendering): at least a third below 0.80
    truths = [bench.true_ffr(make_phantom(("data1", "data2", "data3", "static")[k % 4], 5300 + k,
                                          stenosis_pct=pcts[k], render=False).truth)
              for k in range(8)]
    assert np.mean(np.asarray(truths) < bench.CUTOFF) >= 1.0 / 3.0
    assert all(0.0 < t < 1.0 for t in truths)


def test_the_true_ffr_falls_with_the_stenosis():
    truths = [bench.true_ffr(make_phantom("data1", 11, stenosis_pct=p, render=False).truth)
              for p in (30.0, 50.0, 70.0)]
    assert truths[0] > truths[1] > truths[2]


def _row(err: float, true: float, covered: bool) -> dict:
    return {"ffr_error": err, "ffr_true": true, "ffr": true + err, "covered": covered,
            "decision_agrees": (true + err < 0.8) == (true < 0.8),
            "ffr_ci95": [true + err - 0.05, true + err + 0.05], "mld_error_mm": 0.01}


def test_figures_count_errors_coverage_and_decisions():
    rows = [_row(0.01, 0.9, True), _row(-0.02, 0.7, True), _row(0.15, 0.75, False),
            _row(0.0, 0.85, True)]
    f = bench.figures(rows, [{"ffr_true": 0.6}])
    assert f["cases"] == 5 and f["failed"] == 1
    assert f["ffr_abs_err_median"] == pytest.approx(0.015)
    assert f["ffr_ci95_coverage"] == pytest.approx(0.75)
    assert f["ffr_decision_agreement"] == pytest.approx(0.75)  # 0.75 + 0.15 crossed 0.80
    assert f["true_below_cutoff_fraction"] == pytest.approx(3 / 5)  # the failure counts
    assert f["ffr_ci95_width_median"] == pytest.approx(0.1)


def test_one_case_is_compared_with_the_model_on_its_true_lumen():
    out = bench._case_job(("regular", ("static", 5300), 62.0))
    row = out["row"]
    assert out["failure"] is None and row["stenosis_pct"] == 62.0
    assert row["ffr_true"] < bench.CUTOFF
    assert row["ffr_error"] == pytest.approx(row["ffr"] - row["ffr_true"])
    lo, hi = row["ffr_ci95"]
    assert lo <= row["ffr"] <= hi and row["covered"] == (lo <= row["ffr_true"] <= hi)
    # the reconstruction's lumen error carries into the FFR: here (static, seed 5300, 62 %)
    # the MLD comes out 0.20 mm too wide and the FFR 0.11 too high
    assert np.sign(row["ffr_error"]) == np.sign(row["mld_error_mm"])
    assert abs(row["ffr_error"]) < 0.2
    text = bench.format_table({
        "analytic": bench.analytic(), "seed": 5300, "cases_regular": 1, "cases_per_chain": 0,
        "stenosis_pct_range": [30, 70], "cutoff": 0.8, "suites": {"regular": bench.figures(
            [row], [])}, "overall": bench.figures([row], []), "chains": {}, "anatomy": {},
        "targets": bench.TARGETS, "failures": [], "wall_s": 1.0})
    assert "PASS" in text and "FAIL" not in text and "regular" in text
    # the error's parts sum to it (closed form against the solver's FFR: to 1e-6), and the
    # severe throat carries it: the separation part is the largest
    parts = row["ffr_error_parts"]
    assert sum(parts.values()) == pytest.approx(row["ffr_error"], abs=1e-6)
    assert max(parts, key=lambda p: abs(parts[p])) == "separation"
    assert "error parts, median |part|" in text


def test_the_command_line_refuses_bad_ffr_options_without_output(tmp_path):
    out = tmp_path / "out"
    for flag, value in (("--aortic-pressure", "250"), ("--ffr-velocity", "0"),
                        ("--ffr-split-exponent", "1.5"), ("--ffr-velocity", "fast")):
        result = run_cli("reconstruct", "--demo", "--out", str(out), flag, value)
        assert result.returncode == 2, (flag, value)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and flag in lines[0] and "Traceback" not in result.stderr
        assert not out.exists()


def test_the_demo_report_carries_the_ffr(tmp_path):
    out = tmp_path / "demo"
    result = run_cli("reconstruct", "--demo", "--out", str(out), "--quiet",
                      "--ffr-velocity", "0.4")
    assert result.returncode == 0, result.stderr
    report = json.loads((out / "report.json").read_text())
    block = report["ffr"]
    assert report["measurements"]["ffr"] == block["distal"] == block["ffr"][-1]
    lo, hi = report["measurements_ci95"]["ffr"]
    assert lo <= block["distal"] <= hi and block["ci95"] == [lo, hi]
    assert block["model"]["velocity_m_s"] == 0.4
    assert len(block["s_mm"]) == len(block["ffr"]) == len(block["ci95_lo"])
    assert block["flow_band"]["velocity_m_s"] == [0.25, 0.45]
    assert report["branches"][0]["ffr"]["distal"] == block["distal"]


def test_the_error_parts_split_the_error_by_shapley_values():
    """Only R differs: all of the error is the resistance part. Only a differs (b = 0): the
    viscous part is R / (R + a) - R / (R + a_true). Three differ: the parts sum to the
    error, and each is its Shapley value (checked on one by hand)."""
    pa = 100.0
    true = (40.0, 2.0, 0.5)
    only_r = bench.error_parts((30.0, 2.0, 0.5), true, pa)
    err = bench.distal_ffr(30.0, 2.0, 0.5, pa) - bench.distal_ffr(*true, pa)
    assert only_r["resistance"] == pytest.approx(err, rel=1e-12)
    assert only_r["viscous"] == 0.0 and only_r["separation"] == 0.0
    only_a = bench.error_parts((40.0, 5.0, 0.0), (40.0, 2.0, 0.0), pa)
    assert only_a["viscous"] == pytest.approx(40.0 / 45.0 - 40.0 / 42.0, rel=1e-12)
    rec = (30.0, 5.0, 2.0)
    parts = bench.error_parts(rec, true, pa)
    f = bench.distal_ffr
    assert sum(parts.values()) == pytest.approx(f(*rec, pa) - f(*true, pa), rel=1e-12)
    sep = (2 * (f(40.0, 2.0, 2.0, pa) - f(40.0, 2.0, 0.5, pa))  # b changed first
           + 2 * (f(30.0, 5.0, 2.0, pa) - f(30.0, 5.0, 0.5, pa))  # b changed last
           + (f(30.0, 2.0, 2.0, pa) - f(30.0, 2.0, 0.5, pa))  # b after R only
           + (f(40.0, 5.0, 2.0, pa) - f(40.0, 5.0, 0.5, pa))) / 6  # b after a only
    assert parts["separation"] == pytest.approx(sep, rel=1e-12)
    # figures: the median |part| and which part is largest among errors above 0.03
    rows = [_row(0.01, 0.9, True), _row(0.1, 0.7, True), _row(-0.05, 0.85, True)]
    rows[0]["ffr_error_parts"] = {"resistance": 0.0, "viscous": 0.0, "separation": 0.01}
    rows[1]["ffr_error_parts"] = {"resistance": 0.02, "viscous": 0.0, "separation": 0.08}
    rows[2]["ffr_error_parts"] = {"resistance": -0.04, "viscous": 0.0, "separation": -0.01}
    fig = bench.figures(rows, [])
    assert fig["ffr_error_above_p90_target"] == 2
    assert fig["ffr_error_largest_part"] == {"resistance": 1, "viscous": 0, "separation": 1}
    assert fig["ffr_error_parts_abs_median"]["separation"] == pytest.approx(0.01)
