"""Self-calibration (the paper's sec. 3.4.2): view B calibrated again on the matched
centerline, after the calibration on the clicks.
"""

from __future__ import annotations

import numpy as np

from recon.correspond.matching import match_centerlines
from recon.geometry import ViewGeometry
from recon.pose.calibration import CalibrationResult, calibrate, refine_with_matches
from recon.types import Centerline2D, Matching

__all__ = ["calibration_step", "self_calibrate"]


def calibration_step(name: str, cal: CalibrationResult) -> dict:
    """A calibration step as the report lists it."""
    return {
        "step": name,
        "features": cal.n_features,
        "iterations": cal.iterations,
        "ms": round(cal.elapsed_ms, 2),
        "error_after_px": cal.error_after_px,
    }


def self_calibrate(
    view_a: ViewGeometry,
    view_b_header: ViewGeometry,
    feat_a: np.ndarray,
    feat_b: np.ndarray,
    cl_a: Centerline2D,
    cl_b: Centerline2D,
    cal: CalibrationResult,
    matching: Matching,
    optimizer: str,
    matcher: str,
) -> tuple[CalibrationResult, Matching, list[dict]]:
    """Sec. 3.4.2: add deviation pairs as features and calibrate again; then refine
    over every matched pair (robust, with the priors) and match once more."""
    steps: list[dict] = []
    if len(matching.deviation_a_px):
        pa = np.vstack([feat_a, matching.deviation_a_px])
        pb = np.vstack([feat_b, matching.deviation_b_px])
        cal = calibrate(view_a, view_b_header, pa, pb, method=optimizer)
        steps.append(calibration_step("deviation pairs", cal))
        matching = match_centerlines(cl_a, cl_b, view_a, cal.view_b, method=matcher)
    # Refinement over the matched centerline (about one pair per 4 px of vessel,
    # robust Huber loss, priors centred on the header).
    stride = max(1, len(matching.points_a_px) // 100)
    matched_a, matched_b = matching.points_a_px[::stride], matching.points_b_px[::stride]
    if optimizer == "palm":
        cal = refine_with_matches(
            view_a, view_b_header, feat_a, feat_b, matched_a, matched_b, initial=cal
        )
    else:  # the baselines have no robust loss: plain least squares on the same points
        cal = calibrate(
            view_a,
            view_b_header,
            np.vstack([feat_a, matched_a]),
            np.vstack([feat_b, matched_b]),
            method=optimizer,
        )
    steps.append(calibration_step("matched points", cal))
    matching = match_centerlines(cl_a, cl_b, view_a, cal.view_b, method=matcher)
    return cal, matching, steps

