"""`coronary3d bench calibration-modes`: is the calibrated pose ever worse than the header?

For each phantom case of a suite ("regular": ``PRESET_CYCLE[k % 4]``, seed
``seed + k``; "varied": :func:`recon.synth.suites.varied_cases`, ``cases`` per
imaging chain) both views are traced as the pipeline traces them, and view B is
calibrated from the same inputs in each mode of ``ReconstructionOptions.calibration``:

- "header": no correction;
- "full": the six rig parameters from the clicks;
- "supported": header, translation or full by Laplace evidence
  (:func:`recon.pose.calibration.calibrate_supported`);
- "curves": the full correction from the clicks and the traced curves jointly
  (:func:`recon.pose.calibration_curves.calibrate_with_curves`).

The figure of merit is the **3D error of the segment** with that pose: the truth's
segment points, projected exactly into A and into B's true pose, triangulated with
view A and the calibrated view B (eqs. 2-3), then scaled about view A's source by
the factor that fits the truth best (the baseline length is unobservable from two
views: see docs/benchmarks.md), RMS point-to-point distance in mm. So it measures
the pose alone, not the tracing or the matching.

Per suite and mode: the share of cases whose 3D error is at most the header's plus
:data:`MARGIN_MM` (target at least :data:`TARGET_NO_WORSE`), the share strictly
lower, the median 3D error against the header's, the median rotation error, and
the median curve epipolar distance. Cases whose tracing fails are listed with their
reason.
"""

from __future__ import annotations

import time

import numpy as np

from recon.bench.common import (
    PRESET_CYCLE,
    VARIED_CASES_PER_CHAIN,
    check_suite,
    median,
    parallel_map,
    pose_error,
    scale_free_error_mm,
)
from recon.geometry import triangulate

MODES = ("header", "full", "supported", "curves")
MARGIN_MM = 0.1
TARGET_NO_WORSE = 0.95
CASES = 24  # regular-suite cases when run(cases=None)
STENOSIS_PCT = 50.0


def _case(which):
    from recon.synth import make_phantom

    if which[0] == "regular":
        _, preset, case_seed = which
        return make_phantom(preset, case_seed, stenosis_pct=STENOSIS_PCT), {
            "chain": "regular", "preset": preset, "seed": case_seed}
    from recon.synth.suites import make_suite_case

    spec = which[1]
    return make_suite_case(spec, stenosis_pct=STENOSIS_PCT), {
        "chain": spec.chain, "preset": spec.preset_name, "seed": spec.seed}


def evaluate_case(which) -> dict:
    """One case: the 3D error per mode, or its failure (runs in a worker)."""
    from recon.bench.reconstruct import case_angiograms
    from recon.pipeline import _features
    from recon.pose.calibration import calibrate_supported
    from recon.pose.calibration_curves import calibrate_with_curves
    from recon.trace import trace_pair
    from recon.trace.centerline import compute_vesselness

    case, key = _case(which)
    try:
        a, b = case_angiograms(case)
        va, vb = a.geometry, b.geometry
        seg = case.seeds.segments[0]
        px_mm = (va.pixel_mm_at_isocenter, vb.pixel_mm_at_isocenter)
        vmaps = (compute_vesselness(a.image, pixel_mm=px_mm[0]),
                 compute_vesselness(b.image, pixel_mm=px_mm[1]))
        cl_a, cl_b = trace_pair((a, b), (seg.a, seg.b), vmaps, px_mm, ("auto", "auto"))
        pa, pb = _features(case.seeds, 0, cl_a, cl_b)
        t0 = time.perf_counter()
        full = calibrate_supported(va, vb, pa, pb, candidates=("full",))
        poses = {
            "header": (vb, 0.0, None),
            "full": (full.view_b, (time.perf_counter() - t0) * 1e3, None),
        }
        t0 = time.perf_counter()
        sup = calibrate_supported(va, vb, pa, pb)
        poses["supported"] = (sup.view_b, (time.perf_counter() - t0) * 1e3, sup.correction)
        t0 = time.perf_counter()
        cur = calibrate_with_curves(va, vb, pa, pb, cl_a.points_px, cl_b.points_px, initial=full)
        poses["curves"] = (cur.view_b, (time.perf_counter() - t0) * 1e3,
                           cur.decision["curve_median_px"])
    except ValueError as err:  # CoronaryError included: a failed case is a result
        return {**key, "error": f"{type(err).__name__}: " + " ".join(str(err).split())}
    X = case.truth.segment_X_world
    proj_a, proj_b = case.view_a.project(X), case.view_b_true.project(X)
    row: dict = {**key, "features": len(pa)}
    for mode, (view_b, ms, extra) in poses.items():
        X_rec = triangulate(proj_a, proj_b, va, view_b)
        err, scale = scale_free_error_mm(X_rec, X, va.source_world)
        rot, disp = pose_error(view_b, case.view_b_true, X)
        row[mode] = {"error_mm": err, "scale": scale, "rotation_error_deg": rot,
                     "pose_error_mm": disp, "ms": ms, "extra": extra}
    return row


def _mode_figures(rows: list[dict], mode: str) -> dict:
    err = np.array([r[mode]["error_mm"] for r in rows])
    head = np.array([r["header"]["error_mm"] for r in rows])
    worse = [f"{r['preset']}/{r['seed']}" for r, e, h in zip(rows, err, head, strict=True)
             if e > h + MARGIN_MM]
    return {
        "no_worse_fraction": float(np.mean(err <= head + MARGIN_MM)),
        "lower_fraction": float(np.mean(err < head)),
        "median_error_mm": float(np.median(err)),
        "median_header_error_mm": float(np.median(head)),
        "median_change_mm": float(np.median(err - head)),
        "p90_error_mm": float(np.percentile(err, 90)),
        "median_rotation_error_deg": median(r[mode]["rotation_error_deg"] for r in rows),
        "median_pose_error_mm": median(r[mode]["pose_error_mm"] for r in rows),
        "median_ms": median(r[mode]["ms"] for r in rows),
        "worse_cases": worse,
    }


def summarise(outcomes: list[dict], suite: str) -> dict:
    rows = [o for o in outcomes if "error" not in o]
    failures = [o for o in outcomes if "error" in o]
    if not rows:
        raise ValueError(f"bench calibration-modes: all {len(outcomes)} cases failed, first: "
                         f"{failures[0]}")
    chosen: dict[str, int] = {}
    for r in rows:
        chosen[r["supported"]["extra"]] = chosen.get(r["supported"]["extra"], 0) + 1
    return {
        "suite": suite,
        "cases": len(rows),
        "failures": failures,
        "margin_mm": MARGIN_MM,
        "target_no_worse_fraction": TARGET_NO_WORSE,
        "modes": {m: _mode_figures(rows, m) for m in MODES},
        "supported_chose": chosen,
        "rows": rows,
    }


def run(cases: int | None = None, seed: int = 0, suite: str = "regular",
        workers: int | None = None) -> dict:
    """The 3D error of the segment per calibration mode (module docstring).

    ``cases``: regular-suite cases (None: :data:`CASES`), or per imaging chain for
    ``suite="varied"`` (None: 8). ``workers``: processes (None: up to 2).
    """
    check_suite(suite)
    if suite == "varied":
        from recon.synth.suites import varied_cases

        jobs = [("varied", spec) for spec in
                varied_cases(VARIED_CASES_PER_CHAIN if cases is None else cases, seed)]
    else:
        n = CASES if cases is None else cases
        jobs = [("regular", PRESET_CYCLE[k % len(PRESET_CYCLE)], seed + k) for k in range(n)]
    t0 = time.perf_counter()
    result = summarise(parallel_map(evaluate_case, jobs, workers), suite)
    result["elapsed_s"] = time.perf_counter() - t0
    return result


def format_table(result: dict) -> str:
    """One line per mode."""
    lines = [
        f"bench calibration-modes, {result['suite']} suite: {result['cases']} cases "
        f"({len(result['failures'])} failed); 3D error of the segment with the calibrated "
        "pose, scale-free (RMS mm)",
        f"{'mode':<10}{'<=hdr+0.1':>10}{'<hdr':>7}{'median':>8}{'hdr med':>8}{'change':>8}"
        f"{'p90':>7}{'rot deg':>8}{'pose mm':>8}{'ms':>6}",
    ]
    for mode, f in result["modes"].items():
        lines.append(
            f"{mode:<10}{100 * f['no_worse_fraction']:>9.1f}%{100 * f['lower_fraction']:>6.0f}%"
            f"{f['median_error_mm']:>8.3f}{f['median_header_error_mm']:>8.3f}"
            f"{f['median_change_mm']:>+8.3f}{f['p90_error_mm']:>7.3f}"
            f"{f['median_rotation_error_deg']:>8.2f}{f['median_pose_error_mm']:>8.2f}"
            f"{f['median_ms']:>6.0f}")
    for mode, f in result["modes"].items():
        if f["worse_cases"] and mode != "header":
            lines.append(f"{mode} worse than the header + {result['margin_mm']} mm: "
                         + ", ".join(f["worse_cases"][:12])
                         + (" ..." if len(f["worse_cases"]) > 12 else ""))
    lines.append(f"supported chose {result['supported_chose']}")
    for f in result["failures"]:
        lines.append(f"FAILED {f['chain']} {f['preset']}/{f['seed']}: {f['error']}")
    lines.append(f"target: at least {100 * result['target_no_worse_fraction']:.0f} % of cases "
                 f"no worse than the header + {result['margin_mm']} mm, and a lower median")
    return "\n".join(lines)
