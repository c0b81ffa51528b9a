"""`coronary3d bench calibration`: the paper's Table 2 (Optimize 1-3) on phantom cases.

Cases: the three geometries of the paper's Table 1 (``recon.synth.PRESETS``
"data1", "data2", "data3"), ``runs_per_geometry`` phantom seeds each
(``seed * 10000 + i``; ``run(cases=N)`` sets it, default
:data:`RUNS_PER_GEOMETRY`), each with its own random header error of view B
(``recon.synth.random_header_error``). Features are the seeds' clicks
(``Seeds.correspondences()``: segment ends and bifurcations, with the
phantom's click noise), so K is small (3-5) and the pose is partly fixed by
the priors.

For each run and method ("palm" = Optimize 3, "lm" = Optimize 2, "anneal" =
Optimize 1; annealing only on the first :data:`ANNEAL_RUNS_PER_GEOMETRY` runs of
each geometry because it takes ~0.5 s a run) we record the back-projection
error of eq. (5) before and after (px, and mm on the detector as in Table 2),
the time, the iterations, and the TRUE pose error of the calibrated view B
against the phantom's ``view_b_true``:

- ``rotation_error_deg``: angle of R_est R_true^T;
- ``translation_error_mm``: mean 3D displacement of the truth's segment
  points under the rig error (the motion carrying the true rig onto the
  estimated one), i.e. how far the segment moves relative to B's rig
  (both by :func:`recon.bench.common.pose_error`);
- ``raw_translation_error_mm``: |t_est - t_true| (isocenter positions);
- ``reconstruction_error_mm``: mean 3D distance between the truth's segment
  points and their triangulation (eqs. 2-3) from their exact projections
  with the calibrated geometry: how far the reconstruction moves.

``success`` = final back-projection error < 0.5 px and translation error
(rig displacement) not larger than the header's.

Self-calibration (sec. 3.4.2 and the final bundle adjustment): after the
features-only PALM calibration, matched centerline pairs are added and view
B is recalibrated from the header with the priors and a Huber loss
(:func:`recon.pose.calibration.refine_with_matches`). No matcher is used here:
the TRUE projected segment centerline, sampled every ~1 mm in both views
with 0.3 px noise, stands in for the traced centerlines and is paired in
two ways, both reported:

- "epipolar": each view-A point with the crossing of its epipolar line
  (under the features-only calibration) with the view-B centerline, the
  crossing nearest to the point's relative arc position (a stand-in for
  the matcher; such pairs agree with the geometry that made them, so they
  carry little new information);
- "oracle": the true correspondences (the same 3D sample in both views),
  an upper bound for a perfect matcher.

Curves (``self_calibration.with_curves``): the clicks and the same noisy true
curves, without pairs, by :func:`recon.pose.calibration_curves.calibrate_with_curves`
(the epipolar distance of every curve point to the other view's curve, Cauchy
loss; "pairs" is then the number of curve points).

Landmarks (``landmarks`` in the result): the same PALM calibration with more
clicked landmarks than the seeds hold, spread over the tree: the seeds'
clicks plus the distal ends of the side branches, then also both ends of the
main vessel (true projections with the phantom's click noise). The two views
of one short segment leave the pose weakly determined across the baseline
(a rotation of B about the axis normal to both beams trades against a
translation of B in their plane); landmarks spread wider pin it down.

Two reference poses bound what any calibration from two views can reach
(:func:`reference_poses`): the TRUE rotation and the true translation
across the baseline (everything observable, exact), with the unobservable
translation along the baseline either held at the header's value or set to
its most plausible value under the priors (the minimum of the prior's
Mahalanobis norm given the observable part, which is what a calibration with
priors converges to when the data fix everything else).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from recon.bench.common import pose_error
from recon.geometry import ViewGeometry, epipolar_lines, triangulate
from recon.pose.calibration import (
    CalibrationPriors,
    CalibrationResult,
    calibrate,
    refine_with_matches,
)
from recon.pose.calibration_curves import calibrate_with_curves
from recon.synth import PhantomCase, click_px, make_phantom

__all__ = ["run", "format_table", "pose_errors", "epipolar_pairs", "reference_poses"]

FloatArray = NDArray[np.float64]

GEOMETRIES = ("data1", "data2", "data3")
SUCCESS_PX = 0.5
MATCH_NOISE_PX = 0.3
MATCH_STEP_MM = 1.0
RUNS_PER_GEOMETRY = 50  # phantom seeds per geometry when run(cases=None)
METHODS = ("palm", "lm", "anneal")
ANNEAL_RUNS_PER_GEOMETRY = 5
LANDMARK_SETS = ("seeds", "branch_ends", "branch_and_main_ends")


def pose_errors(
    view_b: ViewGeometry, view_b_true: ViewGeometry, view_a: ViewGeometry, X_world: FloatArray
) -> dict[str, float]:
    """True-pose errors of a calibrated view B (see the module docstring); X_world (P, 3)."""
    rotation_deg, translation_mm = pose_error(view_b, view_b_true, X_world)
    t_est = np.asarray(view_b.t_corr_mm)
    t_true = np.asarray(view_b_true.t_corr_mm)
    X_rec = triangulate(view_a.project(X_world), view_b_true.project(X_world), view_a, view_b)
    return {
        "rotation_error_deg": rotation_deg,
        "translation_error_mm": translation_mm,
        "raw_translation_error_mm": float(np.linalg.norm(t_est - t_true)),
        "reconstruction_error_mm": float(np.mean(np.linalg.norm(X_rec - X_world, axis=1))),
    }


def epipolar_pairs(
    curve_a_px: FloatArray, curve_b_px: FloatArray, view_a: ViewGeometry, view_b: ViewGeometry
) -> tuple[FloatArray, FloatArray]:
    """Pair curve points (N, 2) of A with the crossing of their epipolar line with curve B (M, 2).

    Of several crossings the one nearest to the point's relative arc position
    is taken; points whose line misses curve B are dropped. Returns the
    paired points of A (P, 2) and of B (P, 2).
    """
    lines = epipolar_lines(curve_a_px, view_a, view_b)  # (N, 3), eq. (4)
    signed = lines[:, :2] @ curve_b_px.T + lines[:, 2:3]  # (N, M) signed distances
    crosses = np.signbit(signed[:, :-1]) != np.signbit(signed[:, 1:])  # (N, M - 1)
    n, m = len(curve_a_px), len(curve_b_px)
    expected = np.linspace(0.0, m - 2, n)[:, None]
    gap = np.where(crosses, np.abs(np.arange(m - 1)[None, :] - expected), np.inf)
    j = np.argmin(gap, axis=1)
    rows = np.arange(n)
    keep = np.isfinite(gap[rows, j])
    d0, d1 = signed[rows, j], signed[rows, j + 1]
    frac = np.clip(d0 / np.where(d0 == d1, 1.0, d0 - d1), 0.0, 1.0)
    crossing = curve_b_px[j] + frac[:, None] * (curve_b_px[j + 1] - curve_b_px[j])
    return curve_a_px[keep], crossing[keep]


def reference_poses(
    view_a: ViewGeometry,
    view_b_nominal: ViewGeometry,
    view_b_true: ViewGeometry,
    priors: CalibrationPriors = CalibrationPriors(),  # noqa: B008 (frozen)
) -> tuple[ViewGeometry, ViewGeometry]:
    """View B with every observable pose parameter exact, and two choices of the unobservable one.

    The correction of the nominal view B (whose own correction must be zero)
    is the true rotation and the true translation minus its component along
    the true baseline n (A's source to B's true source: moving B's rig along it
    scales the scene about A's source and changes no image). That component is
    then either 0 (held at the header) or the value g minimising
    t^T S^-1 t with S the priors' translation covariance (diagonal in B's
    u, v, d axes): g = -(n^T S^-1 t_perp) / (n^T S^-1 n).

    Returns
    -------
    (gauge at the header, gauge from the priors) : two corrected views B.
    """
    t_true = np.asarray(view_b_true.t_corr_mm)
    rotvec = np.asarray(view_b_true.rotvec_corr)
    baseline = view_b_true.source_world - view_a.source_world
    n = baseline / np.linalg.norm(baseline)
    t_perp = t_true - (t_true @ n) * n
    axes = view_b_nominal.R_view_from_world  # rows u, v, d
    S_inv = axes.T @ np.diag(1.0 / np.asarray(priors.translation_sigma_mm) ** 2) @ axes
    g = -float(n @ S_inv @ t_perp) / float(n @ S_inv @ n)
    return (
        view_b_nominal.with_correction(rotvec, t_perp),
        view_b_nominal.with_correction(rotvec, t_perp + g * n),
    )


def _record(
    result: CalibrationResult, case: PhantomCase, header: dict[str, float]
) -> dict[str, float]:
    errors = pose_errors(result.view_b, case.view_b_true, case.view_a, case.truth.segment_X_world)
    return {
        "ms": result.elapsed_ms,
        "iterations": result.iterations,
        "error_before_px": result.error_before_px,
        "error_after_px": result.error_after_px,
        "error_before_mm": result.error_before_mm,
        "error_after_mm": result.error_after_mm,
        "converged": result.converged,
        **errors,
        "backprojection_ok": result.error_after_px < SUCCESS_PX,
        "pose_better_than_header": errors["translation_error_mm"] <= header["translation_error_mm"],
        "success": result.error_after_px < SUCCESS_PX
        and errors["translation_error_mm"] <= header["translation_error_mm"],
    }


def _summary(records: list[dict]) -> dict:
    if not records:
        return {"runs": 0}

    def med(key: str) -> float:
        return float(np.median([r[key] for r in records]))

    def rate(key: str) -> float:
        return float(np.mean([bool(r[key]) for r in records]))

    return {
        "runs": len(records),
        "median_ms": med("ms"),
        "median_iterations": med("iterations"),
        "median_error_before_mm": med("error_before_mm"),
        "median_error_after_mm": med("error_after_mm"),
        "median_error_before_px": med("error_before_px"),
        "median_error_after_px": med("error_after_px"),
        "success_rate": rate("success"),
        "converged_rate": rate("converged"),
        "pose_better_than_header_rate": rate("pose_better_than_header"),
        "backprojection_ok_rate": rate("backprojection_ok"),
        "median_rotation_error_deg": med("rotation_error_deg"),
        "median_translation_error_mm": med("translation_error_mm"),
        "median_raw_translation_error_mm": med("raw_translation_error_mm"),
        "median_reconstruction_error_mm": med("reconstruction_error_mm"),
    }


def _pose_summary(records: list[dict], header: list[dict]) -> dict:
    keys = (
        "rotation_error_deg",
        "translation_error_mm",
        "raw_translation_error_mm",
        "reconstruction_error_mm",
    )
    out: dict = {f"median_{k}": float(np.median([r[k] for r in records])) for k in keys}
    out["pose_better_than_header_rate"] = float(
        np.mean(
            [
                r["translation_error_mm"] < h["translation_error_mm"]
                for r, h in zip(records, header, strict=True)
            ]
        )
    )
    out["reconstruction_better_than_header_rate"] = float(
        np.mean(
            [
                r["reconstruction_error_mm"] < h["reconstruction_error_mm"]
                for r, h in zip(records, header, strict=True)
            ]
        )
    )
    if "error_after_px" in records[0]:
        out["median_error_after_px"] = float(np.median([r["error_after_px"] for r in records]))
        out["median_ms"] = float(np.median([r["ms"] for r in records]))
        out["median_pairs"] = float(np.median([r["pairs"] for r in records]))
    return out


def _matched_curves(
    case: PhantomCase, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Noisy true projected centerlines (N, 2) of A and B sampled every ~1 mm, twice noised."""
    X = case.truth.segment_X_world
    step = max(1, int(round(MATCH_STEP_MM / 0.1)))  # the truth is sampled every 0.1 mm
    X = X[::step]
    true_a = case.view_a.project(X)
    true_b = case.view_b_true.project(X)
    noisy_a = true_a + rng.normal(0.0, MATCH_NOISE_PX, true_a.shape)
    noisy_b = true_b + rng.normal(0.0, MATCH_NOISE_PX, true_b.shape)
    return noisy_a, noisy_b, true_a, true_b


def extra_landmarks(
    case: PhantomCase, rng: np.random.Generator, main_ends: bool
) -> tuple[FloatArray, FloatArray]:
    """Clicks (L, 2) in A and B on the side branches' distal ends (and the main vessel's ends).

    True projections clicked as the phantom clicks its seeds (:func:`recon.synth.click_px`).
    """
    vessels = case.truth.vessels
    X = [v[0][-1] for v in vessels[1:]]
    if main_ends:
        X += [vessels[0][0][0], vessels[0][0][-1]]
    X_world = np.asarray(X, dtype=float).reshape(-1, 3)
    clicks_a = click_px(rng, case.view_a.project(X_world))
    return clicks_a, click_px(rng, case.view_b_true.project(X_world))


def run(cases: int | None = None, seed: int = 0) -> dict:
    """Run the benchmark; returns a JSON-ready dict (see the module docstring).

    Parameters
    ----------
    cases : runs (phantom seeds) per geometry; None: :data:`RUNS_PER_GEOMETRY`.
    seed : case i of a geometry uses phantom seed ``seed * 10000 + i``.
    """
    runs_per_geometry = RUNS_PER_GEOMETRY if cases is None else cases
    methods: Sequence[str] = METHODS
    anneal_runs_per_geometry = ANNEAL_RUNS_PER_GEOMETRY
    start = time.perf_counter()
    per_method: dict[str, list[dict]] = {m: [] for m in methods}
    per_geometry: dict[str, dict[str, list[dict]]] = {
        g: {m: [] for m in methods} for g in GEOMETRIES
    }
    header_records: list[dict] = []
    features_only: list[dict] = []
    epipolar: list[dict] = []
    oracle: list[dict] = []
    with_curves: list[dict] = []
    ref_header: list[dict] = []
    ref_prior: list[dict] = []
    n_features: list[int] = []
    landmarks: dict[str, list[dict]] = {k: [] for k in LANDMARK_SETS}
    n_landmarks: dict[str, list[int]] = {k: [] for k in LANDMARK_SETS}
    for geometry in GEOMETRIES:
        for i in range(runs_per_geometry):
            case = make_phantom(geometry, seed * 10000 + i, render=False)
            rng = np.random.default_rng([seed, i, GEOMETRIES.index(geometry)])
            pa, pb, _ = case.seeds.correspondences()
            n_features.append(len(pa))
            X = case.truth.segment_X_world
            header = pose_errors(case.view_b_nominal, case.view_b_true, case.view_a, X)
            header_records.append(header)
            at_header, from_prior = reference_poses(
                case.view_a, case.view_b_nominal, case.view_b_true
            )
            ref_header.append(pose_errors(at_header, case.view_b_true, case.view_a, X))
            ref_prior.append(pose_errors(from_prior, case.view_b_true, case.view_a, X))
            palm_result: CalibrationResult | None = None
            for method in methods:
                if method == "anneal" and i >= anneal_runs_per_geometry:
                    continue
                result = calibrate(case.view_a, case.view_b_nominal, pa, pb, method=method)
                record = _record(result, case, header)
                per_method[method].append(record)
                per_geometry[geometry][method].append(record)
                if method == "palm":
                    palm_result = result
            if palm_result is None:
                palm_result = calibrate(case.view_a, case.view_b_nominal, pa, pb)
            features_only.append(pose_errors(palm_result.view_b, case.view_b_true, case.view_a, X))
            landmark_rng = np.random.default_rng([seed, i, GEOMETRIES.index(geometry), 1])
            for key in LANDMARK_SETS:
                la, lb = pa, pb
                if key != "seeds":
                    ea, eb = extra_landmarks(
                        case, landmark_rng, main_ends=key == "branch_and_main_ends"
                    )
                    la, lb = np.vstack([pa, ea]), np.vstack([pb, eb])
                result = palm_result
                if key != "seeds":
                    result = calibrate(case.view_a, case.view_b_nominal, la, lb)
                landmarks[key].append(_record(result, case, header))
                n_landmarks[key].append(len(la))
            noisy_a, noisy_b, _, _ = _matched_curves(case, rng)
            t0 = time.perf_counter()
            joint = calibrate_with_curves(case.view_a, case.view_b_nominal, pa, pb, noisy_a,
                                          noisy_b)
            with_curves.append({
                **pose_errors(joint.view_b, case.view_b_true, case.view_a, X),
                "error_after_px": joint.error_after_px,
                "ms": (time.perf_counter() - t0) * 1e3,
                "pairs": joint.decision["curve_points"],
            })
            for kind, (ma, mb) in (
                ("epipolar", epipolar_pairs(noisy_a, noisy_b, case.view_a, palm_result.view_b)),
                ("oracle", (noisy_a, noisy_b)),
            ):
                refined = refine_with_matches(
                    case.view_a, case.view_b_nominal, pa, pb, ma, mb, initial=palm_result
                )
                entry = {
                    **pose_errors(refined.view_b, case.view_b_true, case.view_a, X),
                    "error_after_px": refined.error_after_px,
                    "ms": refined.elapsed_ms,
                    "pairs": len(ma),
                }
                (epipolar if kind == "epipolar" else oracle).append(entry)
    header_summary = {
        f"median_{k}": float(np.median([h[k] for h in header_records])) for k in header_records[0]
    }
    return {
        "geometries": list(GEOMETRIES),
        "runs_per_geometry": runs_per_geometry,
        "seed": seed,
        "median_features": float(np.median(n_features)),
        "header": header_summary,
        "methods": {m: _summary(r) for m, r in per_method.items()},
        "per_geometry": {
            g: {m: _summary(r) for m, r in d.items()} for g, d in per_geometry.items()
        },
        "self_calibration": {
            "matches": (
                f"true projected segment centerline every {MATCH_STEP_MM:g} mm with "
                f"{MATCH_NOISE_PX:g} px noise (stand-in for the matcher); 'epipolar' pairs by "
                "the nearest epipolar crossing under the features-only calibration, 'oracle' "
                "by the true correspondence"
            ),
            "header": header_summary,
            "features_only": _pose_summary(features_only, header_records),
            "with_matches_epipolar": _pose_summary(epipolar, header_records),
            "with_matches_oracle": _pose_summary(oracle, header_records),
            "with_curves": _pose_summary(with_curves, header_records),
            "reference_gauge_at_header": _pose_summary(ref_header, header_records),
            "reference_gauge_from_priors": _pose_summary(ref_prior, header_records),
            "runs": len(header_records),
        },
        "landmarks": {
            key: {**_summary(landmarks[key]), "median_landmarks": float(np.median(n))}
            for key, n in n_landmarks.items()
        },
        "success_px": SUCCESS_PX,
        "elapsed_s": time.perf_counter() - start,
    }


def format_table(result: dict) -> str:
    """The paper's Table 2 layout plus the true-pose error, and the self-calibration steps."""
    names = {"anneal": "Optimize 1 (anneal)", "lm": "Optimize 2 (LM)", "palm": "Optimize 3 (PALM)"}
    lines = [
        "Table 2 - calibration from the clicked features "
        f"({result['runs_per_geometry']} runs per geometry, median "
        f"{result['median_features']:g} features; medians)",
        f"{'data':<6} {'method':<20} {'before mm':>10} {'after mm':>10} {'time ms':>9} "
        f"{'iter':>5} {'rot deg':>8} {'trans mm':>9} {'recon mm':>9} {'success':>8} {'runs':>5}",
    ]
    for g, methods in result["per_geometry"].items():
        for m in ("anneal", "lm", "palm"):
            s = methods.get(m)
            if not s or not s.get("runs"):
                continue
            lines.append(
                f"{g:<6} {names.get(m, m):<20} {s['median_error_before_mm']:>10.4f} "
                f"{s['median_error_after_mm']:>10.2e} {s['median_ms']:>9.1f} "
                f"{s['median_iterations']:>5.0f} {s['median_rotation_error_deg']:>8.3f} "
                f"{s['median_translation_error_mm']:>9.2f} "
                f"{s['median_reconstruction_error_mm']:>9.2f} {s['success_rate']:>8.2f} "
                f"{s['runs']:>5d}"
            )
    lines.append("all geometries:")
    for m, s in result["methods"].items():
        if not s.get("runs"):
            continue
        lines.append(
            f"{'all':<6} {names.get(m, m):<20} {s['median_error_before_mm']:>10.4f} "
            f"{s['median_error_after_mm']:>10.2e} {s['median_ms']:>9.1f} "
            f"{s['median_iterations']:>5.0f} {s['median_rotation_error_deg']:>8.3f} "
            f"{s['median_translation_error_mm']:>9.2f} "
            f"{s['median_reconstruction_error_mm']:>9.2f} {s['success_rate']:>8.2f} "
            f"{s['runs']:>5d}"
        )
    sc = result["self_calibration"]
    lines += [
        "",
        f"Self-calibration (PALM + Huber, priors; {sc['runs']} runs). Matches: {sc['matches']}.",
        f"{'step':<22} {'rot deg':>8} {'trans mm':>9} {'raw t mm':>9} {'recon mm':>9} "
        f"{'trans<header':>13} {'recon<header':>13} {'pairs':>6}",
    ]
    for label, key in (
        ("header", "header"),
        ("features only", "features_only"),
        ("+ matches (epipolar)", "with_matches_epipolar"),
        ("+ matches (oracle)", "with_matches_oracle"),
        ("clicks + curves", "with_curves"),
        ("exact, gauge=header", "reference_gauge_at_header"),
        ("exact, gauge by prior", "reference_gauge_from_priors"),
    ):
        s = sc[key]
        better = "-" if key == "header" else f"{s['pose_better_than_header_rate']:.2f}"
        recon = "-" if key == "header" else f"{s['reconstruction_better_than_header_rate']:.2f}"
        pairs = f"{s['median_pairs']:.0f}" if "median_pairs" in s else "-"
        lines.append(
            f"{label:<22} {s['median_rotation_error_deg']:>8.3f} "
            f"{s['median_translation_error_mm']:>9.2f} "
            f"{s['median_raw_translation_error_mm']:>9.2f} "
            f"{s['median_reconstruction_error_mm']:>9.2f} {better:>13} {recon:>13} {pairs:>6}"
        )
    lines += [
        "",
        "Landmarks (PALM, clicks spread over the tree; 'bp ok' = back-projection < "
        f"{result['success_px']} px):",
        f"{'clicks':<26} {'K':>3} {'rot deg':>8} {'trans mm':>9} {'recon mm':>9} "
        f"{'trans<header':>13} {'bp ok':>6} {'success':>8}",
    ]
    for label, key in (
        ("seeds (ends, bifurcations)", "seeds"),
        ("+ branch ends", "branch_ends"),
        ("+ branch and main ends", "branch_and_main_ends"),
    ):
        s = result["landmarks"][key]
        lines.append(
            f"{label:<26} {s['median_landmarks']:>3.0f} {s['median_rotation_error_deg']:>8.3f} "
            f"{s['median_translation_error_mm']:>9.2f} {s['median_reconstruction_error_mm']:>9.2f} "
            f"{s['pose_better_than_header_rate']:>13.2f} {s['backprojection_ok_rate']:>6.2f} "
            f"{s['success_rate']:>8.2f}"
        )
    lines.append(
        "trans = mean displacement of the segment under the rig error; recon = mean 3D error "
        "of the segment triangulated with the calibrated geometry; success = < "
        f"{result['success_px']} px and trans not above the header's; 'exact' rows: true "
        "rotation and cross-baseline translation, the unobservable baseline component held at "
        "the header or set by the priors (the floor of any two-view calibration)."
    )
    return "\n".join(lines)
