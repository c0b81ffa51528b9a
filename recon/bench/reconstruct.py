"""`coronary3d bench reconstruct`: the whole pipeline against phantom ground truth.

For each synthetic case (the paper's Table 1 geometries and the static
preset, several seeds) the full `reconstruct_pair` runs from the rendered
images, the header geometry and the noisy clicks, and its results are
compared with the truth: 3D centerline error, MLD, % diameter stenosis,
segment length, mesh volume, and the true-pose error of calibrated view B
(:func:`recon.bench.common.pose_error`).
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from recon.bench.common import PRESET_CYCLE, pose_error
from recon.geometry import ViewGeometry
from recon.pipeline import ReconstructionOptions, reconstruct_pair
from recon.synth import PhantomCase, make_phantom
from recon.types import Angiogram

CASES = 8  # phantom cases when run(cases=None)
STENOSIS_PCT = 50.0  # diameter stenosis of every case
SELF_CALIBRATION = False  # ReconstructionOptions.self_calibration of the runs


def _angiogram(image: np.ndarray, view: ViewGeometry, name: str) -> Angiogram:
    return Angiogram(
        image=image.astype(np.float32),
        geometry=view,
        path=name,
        frame_index=0,
        frame_reason="single frame",
        n_frames=1,
        frame_time_ms=None,
        frames=None,
        geometry_notes=(),
        info={},
    )


def polyline_distance_mm(points: np.ndarray, truth_dense: np.ndarray) -> np.ndarray:
    """Distance (N,) from points (N, 3) to a densely sampled polyline (M, 3)."""
    dist, _ = cKDTree(truth_dense).query(points)
    return dist


def scale_free_rms_mm(X_world: np.ndarray, truth_dense: np.ndarray, source_a: np.ndarray
                      ) -> tuple[float, float]:
    """3D RMS error after the best scaling about view A's source, and that scale.

    Two views fix view B's pose only up to the length of the baseline (moving
    B's rig along the line between the sources changes no epipolar line), so
    a reconstruction is determined up to a scaling about A's source: this is
    the error that remains once that unobservable factor is removed.
    """
    from scipy.optimize import minimize_scalar

    tree = cKDTree(truth_dense)

    def rms(k: float) -> float:
        d, _ = tree.query(source_a + k * (X_world - source_a))
        return float(np.sqrt(np.mean(d**2)))

    res = minimize_scalar(rms, bounds=(0.9, 1.1), method="bounded",
                          options={"xatol": 1e-6})
    return float(res.fun), float(res.x)


def evaluate_case(case: PhantomCase, options: ReconstructionOptions) -> dict:
    a = _angiogram(case.image_a, case.view_a, f"{case.preset}-{case.seed}-a")
    b = _angiogram(case.image_b, case.view_b_nominal, f"{case.preset}-{case.seed}-b")
    t0 = time.perf_counter()
    rec = reconstruct_pair(a, b, case.seeds, options)
    wall_ms = (time.perf_counter() - t0) * 1000.0
    truth = case.truth
    err = polyline_distance_mm(rec.centerline_3d.X_world, truth.segment_X_world)
    m = rec.measurements
    rms_free, scale = scale_free_rms_mm(rec.centerline_3d.X_world, truth.segment_X_world,
                                        rec.view_a.source_world)
    true_length = float(truth.segment_s_mm[-1])
    rot_before, disp_before = pose_error(case.view_b_nominal, case.view_b_true,
                                         truth.segment_X_world)
    rot_after, disp_after = pose_error(rec.view_b, case.view_b_true, truth.segment_X_world)
    return {
        "preset": case.preset,
        "seed": case.seed,
        "centerline_3d_rms_mm": float(np.sqrt(np.mean(err**2))),
        "centerline_3d_max_mm": float(np.max(err)),
        "centerline_3d_rms_scale_free_mm": rms_free,
        "baseline_scale": scale,
        "mld_mm": m.mld_mm,
        "mld_true_mm": truth.mld_mm,
        "mld_error_mm": m.mld_mm - truth.mld_mm,
        "diameter_stenosis_pct": m.diameter_stenosis_pct,
        "diameter_stenosis_true_pct": truth.stenosis_diameter_pct,
        "diameter_stenosis_error_pct": m.diameter_stenosis_pct - truth.stenosis_diameter_pct,
        "length_mm": m.segment_length_mm,
        "length_true_mm": true_length,
        "length_error_pct": 100.0 * (m.segment_length_mm - true_length) / true_length,
        "lesion_length_mm": m.lesion_length_mm,
        "lesion_length_true_mm": truth.stenosis_length_mm,
        "volume_error_pct": 100.0
        * (float(rec.surface.mesh.volume) - truth.segment_volume_mm3)
        / truth.segment_volume_mm3,
        "watertight": bool(rec.surface.mesh.is_watertight),
        "pose_rotation_error_deg_before": rot_before,
        "pose_rotation_error_deg_after": rot_after,
        "pose_displacement_mm_before": disp_before,
        "pose_displacement_mm_after": disp_after,
        "backprojection_rms_px_a": rec.metrics["a"]["rms_px"],
        "backprojection_rms_px_b": rec.metrics["b"]["rms_px"],
        "backprojection_median_px_a": rec.metrics["a"]["median_px"],
        "backprojection_median_px_b": rec.metrics["b"]["median_px"],
        "wall_ms": wall_ms,
        "timings_ms": rec.timings_ms,
    }


def run(cases: int | None = None, seed: int = 0) -> dict:
    """Run the end-to-end benchmark on ``cases`` phantom cases; medians and rows.

    ``cases`` None means :data:`CASES`; case k is preset ``PRESET_CYCLE[k % 4]``
    with seed ``seed + k``.
    """
    cases = CASES if cases is None else cases
    stenosis_pct = STENOSIS_PCT
    self_calibration = SELF_CALIBRATION
    options = ReconstructionOptions(self_calibration=self_calibration)
    rows = []
    failures = []
    for k in range(cases):
        preset = PRESET_CYCLE[k % len(PRESET_CYCLE)]
        case = make_phantom(preset, seed + k, stenosis_pct=stenosis_pct)
        try:
            rows.append(evaluate_case(case, options))
        except ValueError as err:  # a failed case is a result, not a crash of the bench
            failures.append({"preset": preset, "seed": seed + k, "error": str(err)})
    if not rows:
        raise ValueError(f"bench reconstruct: all {cases} cases failed, first: {failures[0]}")

    def med(key: str, absolute: bool = False) -> float:
        values = np.array([r[key] for r in rows], dtype=float)
        return float(np.median(np.abs(values) if absolute else values))

    stages = sorted({s for r in rows for s in r["timings_ms"]})
    return {
        "cases": len(rows),
        "failures": failures,
        "self_calibration": self_calibration,
        "centerline_3d_rms_mm": med("centerline_3d_rms_mm"),
        "centerline_3d_rms_scale_free_mm": med("centerline_3d_rms_scale_free_mm"),
        "abs_mld_error_mm": med("mld_error_mm", absolute=True),
        "abs_diameter_stenosis_error_pct": med("diameter_stenosis_error_pct", absolute=True),
        "abs_length_error_pct": med("length_error_pct", absolute=True),
        "abs_volume_error_pct": med("volume_error_pct", absolute=True),
        "max_abs_mld_error_mm": float(max(abs(r["mld_error_mm"]) for r in rows)),
        "max_abs_diameter_stenosis_error_pct": float(
            max(abs(r["diameter_stenosis_error_pct"]) for r in rows)
        ),
        "watertight_rate": float(np.mean([r["watertight"] for r in rows])),
        "pose_improved_rate": float(
            np.mean([r["pose_displacement_mm_after"] < r["pose_displacement_mm_before"]
                     for r in rows])
        ),
        "median_pipeline_ms": med("wall_ms"),
        "median_stage_ms": {
            s: float(np.median([r["timings_ms"].get(s, 0.0) for r in rows])) for s in stages
        },
        "rows": rows,
    }


def format_table(result: dict) -> str:
    lines = [
        f"End-to-end reconstruction on {result['cases']} phantom cases "
        f"(self-calibration {'on' if result['self_calibration'] else 'off'})",
        "",
        f"{'case':<10} {'3D rms mm':>9} {'scalefree':>9} {'MLD err':>8} {'%DS err':>8} "
        f"{'len err%':>8} "
        f"{'vol err%':>8} {'pose mm before->after':>22} {'ms':>7}",
    ]
    for r in result["rows"]:
        lines.append(
            f"{r['preset'] + '/' + str(r['seed']):<10} {r['centerline_3d_rms_mm']:9.3f} "
            f"{r['centerline_3d_rms_scale_free_mm']:9.3f} "
            f"{r['mld_error_mm']:+8.3f} {r['diameter_stenosis_error_pct']:+8.1f} "
            f"{r['length_error_pct']:+8.2f} {r['volume_error_pct']:+8.1f} "
            f"{r['pose_displacement_mm_before']:10.2f} -> {r['pose_displacement_mm_after']:<8.2f}"
            f" {r['wall_ms']:7.0f}"
        )
    for f in result.get("failures", []):
        lines.append(f"{f['preset'] + '/' + str(f['seed']):<10} FAILED: {f['error']}")
    lines += [
        "",
        f"median 3D centerline RMS error  {result['centerline_3d_rms_mm']:.3f} mm "
        f"({result['centerline_3d_rms_scale_free_mm']:.3f} mm without the unobservable "
        "baseline scale)",
        f"median |MLD error|              {result['abs_mld_error_mm']:.3f} mm "
        f"(max {result['max_abs_mld_error_mm']:.3f})",
        f"median |% diameter stenosis err| {result['abs_diameter_stenosis_error_pct']:.1f} points "
        f"(max {result['max_abs_diameter_stenosis_error_pct']:.1f})",
        f"median |length error|           {result['abs_length_error_pct']:.2f} %",
        f"median |mesh volume error|      {result['abs_volume_error_pct']:.1f} %",
        f"watertight meshes               {result['watertight_rate'] * 100:.0f} %",
        f"pose better than header         {result['pose_improved_rate'] * 100:.0f} %",
        f"median pipeline time            {result['median_pipeline_ms']:.0f} ms "
        + ", ".join(f"{k} {v:.0f}" for k, v in result["median_stage_ms"].items()),
        f"failed cases                    {len(result.get('failures', []))}",
    ]
    return "\n".join(lines)
