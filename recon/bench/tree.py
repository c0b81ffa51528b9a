"""`coronary3d bench reconstruct --suite tree`: phantom trees with bifurcation lesions.

Case k is preset ``PRESET_CYCLE[k % 4]`` (the paper's Table 1 geometries
and the static pair) with seed ``seed + k`` and lesion
``TREE_LESIONS[k % 3]`` (:func:`recon.synth.tree.make_tree_case`: the main
lesion on a bifurcation's shoulder, a 50 % ostial side-branch lesion, or
both at one bifurcation); every side branch leaving the main segment is
clicked as a branch. :func:`recon.tree.reconstruct_tree` runs on the
rendered images and header geometry, and is compared with the truth:

- per segment: MLD and reference diameter (the main's as the regular
  suite; a branch's true MLD is the least true diameter from its true
  carina to its distal click, its reference the undiseased taper there).
  ``mld_err_*`` and ``ref_diam_err_*`` are over the segments with a lesion
  (true MLD below :data:`LESION_FRACTION` of its reference: the main
  segment and the narrowed side-branch ostia); a healthy branch's "MLD" is
  only its thinnest, usually distal, stretch, reported apart
  (``mld_err_all_*``, every segment);
- per bifurcation: the bifurcation angle, with the definitions of
  :mod:`recon.bifurcation` applied to the true centerlines;
- the pose of view B (mean displacement over the tree's true points, as
  the regular suite: better than the header when smaller), and the same
  for the tree's calibration with every branch's matched points added
  (self-calibration);
- the tree mesh: watertight and one connected component.

A case whose reconstruction raises is a failure with its one-line reason.
"""

from __future__ import annotations

import resource
import time

import numpy as np

from recon.bench.common import PRESET_CYCLE, pose_error
from recon.bifurcation import bifurcation_angles_deg, carina_s_mm
from recon.errors import CoronaryError
from recon.pipeline import ReconstructionOptions
from recon.synth.tree import SAMPLE_STEP_MM, TREE_LESIONS, TreeCase, make_tree_case
from recon.tree import reconstruct_tree, tree_calibration

__all__ = ["run_tree", "format_tree", "CASES"]

CASES = 12  # tree cases when cases is None
STENOSIS_PCT = 50.0
LESION_FRACTION = 0.75  # a segment "with a lesion": true MLD below this x its reference


def _branch_truth(tc: TreeCase, j: int) -> tuple[float, float]:
    """(true MLD, true reference diameter at it) mm of segment j of the tree case."""
    truth = tc.case.truth
    if j == 0:
        return truth.mld_mm, truth.reference_diameter_mm
    X, r = truth.vessels[tc.vessels[j]]
    main_X, main_r = truth.vessels[0]
    s = np.arange(len(X)) * SAMPLE_STEP_MM
    s_c = carina_s_mm(X, main_X, main_r)
    inside = (s >= s_c) & (s <= tc.end_s_mm[j])
    taper = r[0] + (r[-1] - r[0]) * s / s[-1]
    i = int(np.flatnonzero(inside)[np.argmin(r[inside])])
    return float(2 * r[i]), float(2 * taper[i])


def _case(preset: str, seed: int, lesion: str) -> dict:
    tc = make_tree_case(preset, seed, lesion, stenosis_pct=STENOSIS_PCT)
    from recon.bench.reconstruct import case_angiograms

    a, b = case_angiograms(tc.case)
    t0 = time.perf_counter()
    rec = reconstruct_tree(a, b, tc.seeds)
    wall_ms = (time.perf_counter() - t0) * 1000.0
    truth = tc.case.truth
    segments = []
    for j, branch in enumerate(rec.branches):
        mld_true, ref_true = _branch_truth(tc, j)
        m = branch.measurements
        segments.append({
            "name": tc.seeds.segments[j].name,
            "mld_mm": m.mld_mm, "mld_true_mm": mld_true, "mld_error_mm": m.mld_mm - mld_true,
            "reference_diameter_mm": m.reference_diameter_mm,
            "reference_true_mm": ref_true,
            "ref_diam_error_mm": m.reference_diameter_mm - ref_true,
            "diameter_stenosis_pct": m.diameter_stenosis_pct,
        })
    bifurcations = []
    main_X, main_r = truth.vessels[0]
    for bq in rec.bifurcations:
        j = tc.seeds.segment_index(bq.branch)
        true_angle, true_prox, _ = bifurcation_angles_deg(main_X, main_r,
                                                          truth.vessels[tc.vessels[j]][0])
        bifurcations.append({
            "name": bq.name, "angle_deg": bq.bifurcation_angle_deg, "angle_true_deg": true_angle,
            "angle_error_deg": bq.bifurcation_angle_deg - true_angle,
            "proximal_angle_error_deg": bq.proximal_angle_deg - true_prox,
            "gap_mm": bq.gap_mm, "join_shift_mm": bq.join_shift_mm, "medina": bq.medina,
        })
    X_tree = np.vstack([truth.segment_X_world] + [truth.vessels[v][0] for v in tc.vessels[1:]])
    _, before = pose_error(tc.case.view_b_nominal, tc.case.view_b_true, X_tree)
    _, after = pose_error(rec.first.view_b, tc.case.view_b_true, X_tree)
    # the same tree's calibration with the matched points of every branch added
    traced = [(branch.centerline_a, branch.centerline_b) for branch in rec.branches]
    matched = tree_calibration(a, b, tc.seeds, traced,
                               ReconstructionOptions(self_calibration=True))
    _, after_matched = pose_error(matched.view_b, tc.case.view_b_true, X_tree)
    mesh = rec.tree_surface.mesh
    return {
        "preset": preset, "seed": seed, "lesion": lesion, "segments": segments,
        "bifurcations": bifurcations,
        "pose_displacement_mm_before": before, "pose_displacement_mm_after": after,
        "pose_displacement_mm_after_matched_points": after_matched,
        "watertight": bool(mesh.is_watertight), "components": rec.tree_surface.components,
        "voxel_mm": rec.tree_surface.voxel_mm, "grid_voxels": rec.tree_surface.grid_voxels,
        "wall_ms": wall_ms,
    }


def run_tree(cases: int | None = None, seed: int = 0) -> dict:
    """Run the tree suite (module docstring); the figures, the rows and the failures."""
    cases = CASES if cases is None else cases
    rows, failed = [], []
    for k in range(cases):
        preset = PRESET_CYCLE[k % len(PRESET_CYCLE)]
        lesion = TREE_LESIONS[k % len(TREE_LESIONS)]
        try:
            rows.append(_case(preset, seed + k, lesion))
        except (CoronaryError, ValueError) as err:
            reason = " ".join(str(err).split())
            failed.append({"preset": preset, "seed": seed + k, "lesion": lesion,
                           "error": reason})
    return summarise(rows, failed)


def summarise(rows: list[dict], failed: list[dict]) -> dict:
    """The suite's figures from its case rows (:func:`run_tree`)."""
    segs = [s for r in rows for s in r["segments"]]
    lesion = [s for s in segs if s["mld_true_mm"] < LESION_FRACTION * s["reference_true_mm"]]
    mld_all = np.array([s["mld_error_mm"] for s in segs], dtype=float)
    mld = np.array([s["mld_error_mm"] for s in lesion], dtype=float)
    ref = np.array([s["ref_diam_error_mm"] for s in lesion], dtype=float)
    ang = np.array([b["angle_error_deg"] for r in rows for b in r["bifurcations"]], dtype=float)
    gaps = [b["gap_mm"] for r in rows for b in r["bifurcations"]]

    def mean(v: np.ndarray) -> float | None:
        return float(np.mean(v)) if len(v) else None

    def sd(v: np.ndarray) -> float | None:
        return float(np.std(v, ddof=1)) if len(v) > 1 else None

    return {
        "suite": "tree",
        "cases": len(rows),
        "segments": len(segs),
        "lesion_segments": len(lesion),
        "bifurcation_count": int(len(ang)),
        "mld_err_mean_mm": mean(mld),
        "mld_err_sd_mm": sd(mld),
        "mld_err_all_mean_mm": mean(mld_all),
        "mld_err_all_sd_mm": sd(mld_all),
        "ref_diam_err_mean_mm": mean(ref),
        "ref_diam_err_sd_mm": sd(ref),
        "bifurcation_angle_err_mean_deg": mean(ang),
        "bifurcation_angle_err_sd_deg": sd(ang),
        "max_gap_mm": float(max(gaps)) if gaps else None,
        "pose_better_than_header": float(np.mean(
            [r["pose_displacement_mm_after"] < r["pose_displacement_mm_before"] for r in rows]))
        if rows else None,
        "pose_better_than_header_with_matched_points": float(np.mean(
            [r["pose_displacement_mm_after_matched_points"] < r["pose_displacement_mm_before"]
             for r in rows])) if rows else None,
        "pose_displacement_median_mm": {
            key: float(np.median([r[f"pose_displacement_mm_{key}"] for r in rows]))
            for key in ("before", "after", "after_matched_points")} if rows else None,
        "watertight_single_component": float(np.mean(
            [r["watertight"] and r["components"] == 1 for r in rows])) if rows else None,
        "failed": failed,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "rows": rows,
    }


def format_tree(result: dict) -> str:
    """Plain-text summary of a :func:`run_tree` result."""
    def f(key: str, fmt: str = "{:+.3f}") -> str:
        v = result.get(key)
        return "-" if v is None else fmt.format(v)

    lines = [
        f"Tree suite: {result['cases']} cases ({result['segments']} segments, "
        f"{result['lesion_segments']} with a lesion, {result['bifurcation_count']} "
        f"bifurcations), {len(result['failed'])} failed",
        f"MLD error mean / SD (mm), lesions   {f('mld_err_mean_mm')} / "
        f"{f('mld_err_sd_mm', '{:.3f}')}",
        f"  every segment                     {f('mld_err_all_mean_mm')} / "
        f"{f('mld_err_all_sd_mm', '{:.3f}')}",
        f"reference diameter error mean / SD  {f('ref_diam_err_mean_mm')} / "
        f"{f('ref_diam_err_sd_mm', '{:.3f}')} mm (lesions)",
        f"bifurcation angle error mean / SD   {f('bifurcation_angle_err_mean_deg', '{:+.2f}')} / "
        f"{f('bifurcation_angle_err_sd_deg', '{:.2f}')} deg",
        f"largest gap at a bifurcation (mm)   {f('max_gap_mm', '{:.3f}')}",
        f"pose better than header             {f('pose_better_than_header', '{:.2f}')} "
        f"(with every branch's matched points: "
        f"{f('pose_better_than_header_with_matched_points', '{:.2f}')})",
        f"watertight, one component           {f('watertight_single_component', '{:.2f}')}",
        f"peak memory (MB)                    {f('peak_rss_mb', '{:.0f}')}",
    ]
    for fail in result["failed"]:
        lines.append(f"failed {fail['preset']}-{fail['seed']} ({fail['lesion']}): {fail['error']}")
    return "\n".join(lines)
