"""The matching benchmark's per-case evaluation (recon/bench/matching.py)."""

from __future__ import annotations

from recon.bench.matching import evaluate_case, foreshortening_ratio
from recon.synth import make_phantom


def test_evaluate_case_separates_tracing_from_matching() -> None:
    """data3 seed 0 foreshortens part of the segment in one view (ratio > 3).

    With B's true geometry and the true projected centerlines the CBOCD step
    (match3) follows it within 0.1 mm, while the fixed step of 2 (match2)
    cannot: at least twice the error.
    """
    case = make_phantom("data3", 0)
    assert foreshortening_ratio(case) > 3.0
    record = evaluate_case(case)
    assert record["source"] == "traced"
    m2, m3 = record["methods"]["match2"], record["methods"]["match3"]
    for m in (m2, m3):
        assert {
            "centerline_3d_rms_mm",
            "centerline_3d_rms_true_geometry_mm",
            "centerline_3d_rms_true_2d_mm",
        } <= set(m)
    assert m3["centerline_3d_rms_true_2d_mm"] < 0.1
    assert m2["centerline_3d_rms_true_2d_mm"] > 2.0 * m3["centerline_3d_rms_true_2d_mm"]
