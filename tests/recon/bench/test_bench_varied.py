"""The varied suite's benches: JSON keys per chain and overall, failures counted, stability."""

from __future__ import annotations

import json

import numpy as np
import pytest

import recon.synth.suites as suites
from recon.bench import centerline, reconstruct
from recon.bench.common import jitter_seeds, rigid_rms_mm
from recon.geometry import rotation_from_rotvec
from recon.synth import make_phantom

CHAIN_KEYS = {"cases", "traces", "trace_success", "trace_success_answered", "refused", "lost",
              "centerline_rms_px", "radius_bias_pct", "radius_mae_px"}
RECON_KEYS = {"cases", "succeeded", "failed", "abs_mld_error_mm", "p90_abs_mld_error_mm",
              "abs_length_error_pct", "abs_volume_error_pct", "centerline_3d_rms_rigid_mm",
              "max_centerline_3d_rms_rigid_mm", "failures", "trace_success",
              "traces_lost_unflagged"}


@pytest.fixture
def tiny_suite(monkeypatch):
    """Two 512 px cases of two chains (the full suite takes minutes)."""
    real = suites.varied_cases

    def tiny(n_per_chain: int = 8, seed: int = 0):
        cases = real(1, seed)
        return [c for c in cases if c.chain in ("sharp-display", "glare-8bit")]

    monkeypatch.setattr(suites, "varied_cases", tiny)


def test_bench_centerline_varied_keys(tiny_suite):
    result = centerline.run(cases=1, suite="varied")
    json.dumps(result, default=float)
    assert result["suite"] == "varied" and set(result["chains"]) == {"sharp-display",
                                                                    "glare-8bit"}
    # the phantom's guiding catheter (glare-8bit renders one, sharp-display none); in the
    # glare case (a loop, seed 300) it is found in one view of two
    glare, sharp = result["chains"]["glare-8bit"], result["chains"]["sharp-display"]
    assert glare["catheter_views"] == 2 and glare["catheter_found"] == 0.5
    assert sharp["catheter_views"] == 0 and sharp["catheter_found"] is None
    assert glare["catheter_false_per_view"] == 0 == sharp["catheter_false_per_view"]
    for figures in [*result["chains"].values(), result["overall"]]:
        assert CHAIN_KEYS <= set(figures)
    assert result["overall"]["traces"] == 4 and len(result["rows"]) == 4
    # A refused trace is a failure, not skipped.
    for row in result["rows"]:
        assert row["status"] in ("ok", "lost", "refused")
        assert row["success"] == (row["status"] == "ok")
        if row["status"] != "refused":  # only a refusal is answered
            assert row["answered_success"] == row["success"]
            assert row["answered_waypoints"] == 0
    assert "overall" in centerline.format_table(result)
    for row in result["rows"]:  # every click measured, refused traces included
        assert len(row["click_error_px"]) == len(row["snap_error_px"]) >= 2
    o = result["overall"]
    assert 0.0 < o["click_error_px_median"] < 1.5  # the click model's 0.7 px per axis
    assert 0.0 <= o["snap_error_px_over_2"] <= 1.0


def test_a_refusal_is_answered_with_a_waypoint_on_the_truth_where_it_asks(monkeypatch):
    """The simulated clinician clicks the true segment nearest the place a refusal names,
    puts that waypoint in order along the segment, and stops at a refusal that names no
    place or after ANSWER_ROUNDS waypoints."""
    from recon.trace.trace_error import TraceError

    seg = np.column_stack([np.arange(0.0, 100.0, 0.1), np.full(1000, 50.0)])
    clicks = np.array([[0.0, 50.0], [60.0, 50.0], [99.9, 50.0]])
    seen = []

    def refuse_then_succeed(image, view, clicks_px, case, name, vmap):
        seen.append(np.array(clicks_px))
        if len(seen) == 1:
            raise TraceError("again", near_px=(80.0, 47.0))
        return {"success": True}

    monkeypatch.setattr(centerline, "_evaluate_varied_view", refuse_then_succeed)
    first = TraceError("between click 1 and click 2", near_px=(30.0, 53.0))
    out = centerline._answered(None, None, clicks, None, "A", None, seg, first,
                               np.random.default_rng(0))
    assert out == {"answered_success": True, "answered_waypoints": 2}
    assert [len(c) for c in seen] == [4, 5]
    np.testing.assert_allclose(seen[1][[0, 2, 4]], clicks, atol=0)  # the clicks kept
    assert abs(seen[1][1, 0] - 30.0) < 3.0 and abs(seen[1][3, 0] - 80.0) < 3.0  # in order
    assert np.all(np.abs(seen[1][[1, 3], 1] - 50.0) < 3.0)  # on the truth, click noise

    seen.clear()
    out = centerline._answered(None, None, clicks, None, "A", None, seg,
                               TraceError("no place"), np.random.default_rng(0))
    assert out == {"answered_success": False, "answered_waypoints": 0} and not seen

    def always_refuse(image, view, clicks_px, case, name, vmap):
        seen.append(np.array(clicks_px))
        raise TraceError("still", near_px=(50.0, 50.0))

    monkeypatch.setattr(centerline, "_evaluate_varied_view", always_refuse)
    out = centerline._answered(None, None, clicks, None, "A", None, seg, first,
                               np.random.default_rng(0))
    assert out == {"answered_success": False, "answered_waypoints": centerline.ANSWER_ROUNDS}
    assert [len(c) for c in seen] == [4, 5][: centerline.ANSWER_ROUNDS]


def test_click_errors_measure_the_snap_against_the_true_centre_line():
    """A click 3 px off a dark horizontal tube's centre: 3 px as clicked, near 0 snapped."""
    rows, cols = np.mgrid[0:128, 0:160].astype(float)
    image = 1.0 - 0.5 * np.clip(1.0 - ((rows - 60.0) / 4.0) ** 2, 0.0, None) ** 0.5
    from recon.trace.centerline import compute_vesselness

    vmap = compute_vesselness(image.astype(np.float32))
    seg = np.column_stack([np.arange(20.0, 140.0, 0.1), np.full(1200, 60.0)])
    err = centerline._click_errors(vmap, np.array([[80.0, 63.0]]), seg)
    assert err["click_error_px"][0] == pytest.approx(3.0)
    assert err["snap_error_px"][0] < 0.3


def test_bench_reconstruct_varied_keys_and_stability(tiny_suite):
    result = reconstruct.run(cases=1, suite="varied", jitter=1)
    json.dumps(result, default=float)
    for figures in [*result["chains"].values(), result["overall"]]:
        assert RECON_KEYS <= set(figures)
    assert result["overall"]["cases"] == 2
    st = result["stability"]
    assert st["jitter_px"] == 2.0 and len(st["cases"]) == 2
    for key in ("stable_fraction", "mld_spread_mm_median", "ds_spread_pct_median",
                "site_spread_mm_median", "lesion_set_stable", "lesion_set_stable_delta",
                "lesion_set_stable_completed", "lesion_set_stable_unmerged",
                "lesion_set_kept_or_borderline"):
        assert key in st["overall"]
    assert "click stability" in reconstruct.format_table(result)
    # issue 46: each case's lesion sets, base run first, and whether they are all the same
    from recon.lumen.lesions import lesion_sets_equal

    for case in st["cases"]:
        sets = case["lesion_sets"]
        assert len(sets) == case["runs"] + (not case["base_failed"])
        same = all(lesion_sets_equal(sets[0], other) for other in sets[1:])
        assert case["lesion_set_stable"] == (same and case["failed_runs"] == 0
                                             and not case["base_failed"])
        assert all(les["end_s_mm"] > les["start_s_mm"] for run in sets for les in run)
    assert st["overall"]["lesion_set_stable"] == np.mean(
        [c["lesion_set_stable"] for c in st["cases"]])


def test_final_traces_are_judged_against_the_truth_and_a_silent_loss_is_counted():
    """The end-to-end rows judge each view's final trace as ``bench centerline`` does: the
    projected truth itself is on it; the truth shifted 3 px across is lost, and counts
    as silent only when the cross-view check named no stretch of that view."""
    from types import SimpleNamespace

    from recon.correspond.consistency import Stretch
    from recon.types import Centerline2D

    case = make_phantom("data1", 0, render=False)
    pts_a = case.truth.segment_px(case.view_a)
    pts_b = case.truth.segment_px(case.view_b_true)
    shift = np.array([0.0, 3.0])

    def rec(b_points, stretches):
        def cl(p):
            return Centerline2D(points_px=p, radius_px=np.full(len(p), 3.0),
                                brightness=np.zeros(len(p)))
        return SimpleNamespace(centerline_a=cl(pts_a), centerline_b=cl(b_points),
                               consistency=SimpleNamespace(stretches=stretches))

    on = reconstruct._trace_figures(case, rec(pts_b, []))
    assert not on["trace_lost_a"] and not on["trace_lost_b"]
    assert on["trace_gap_px_b"] < 0.1
    off = reconstruct._trace_figures(case, rec(pts_b + shift, []))
    assert off["trace_lost_b"] and off["trace_lost_unflagged_b"]
    assert off["trace_gap_px_b"] == pytest.approx(3.0, abs=0.3)
    told = Stretch("b", "off_vessel", 1.0, 4.0, (0.0, 0.0), 3.0, "off the vessel in view B")
    flagged = reconstruct._trace_figures(case, rec(pts_b + shift, [told]))
    assert flagged["trace_lost_b"] and not flagged["trace_lost_unflagged_b"]
    assert not flagged["trace_lost_unflagged_a"]


def test_unknown_suite_is_refused():
    with pytest.raises(ValueError, match="unknown suite"):
        centerline.run(cases=1, suite="nope")


def test_jittered_clicks_stay_within_the_disc():
    case = make_phantom("data1", 0, render=False)
    rng = np.random.default_rng(0)
    moved = jitter_seeds(case.seeds, rng, 2.0, (512, 512), (512, 512))
    a0, a1 = case.seeds.segments[0].a, moved.segments[0].a
    d = np.linalg.norm(a1 - a0, axis=1)
    assert np.all(d <= 2.0 + 0.08) and np.any(d > 0.1)
    assert len(moved.features) == len(case.seeds.features)


def test_rigid_rms_removes_a_rotation_and_translation_but_not_a_scale():
    s = np.linspace(0, 1, 400)
    truth = np.column_stack([60 * s, 10 * np.sin(4 * s), 5 * s**2])
    R = rotation_from_rotvec(np.array([0.02, -0.03, 0.05]))
    moved = truth @ R.T + [3.0, -2.0, 1.0]
    assert rigid_rms_mm(moved, truth) < 1e-3
    assert rigid_rms_mm(truth * 1.02, truth) > 0.03  # a scale is not aligned away


def test_cli_refuses_a_suite_or_jitter_where_there_is_none(capsys):
    from recon.cli import main

    assert main(["bench", "calibration", "--suite", "varied"]) == 2
    assert "no --suite varied" in capsys.readouterr().err
    assert main(["bench", "centerline", "--jitter", "3"]) == 2
    assert "--jitter" in capsys.readouterr().err
