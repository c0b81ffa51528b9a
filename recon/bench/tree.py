"""`coronary3d bench reconstruct --suite tree`: phantom trees with bifurcation lesions.

Case k has seed ``seed + k``, lesion ``TREE_LESIONS[k % 3]``
(:func:`recon.synth.tree_case.make_tree_case`: the main lesion on a
bifurcation's shoulder, an ostial side-branch lesion, or both at one
bifurcation; diameter stenosis drawn from :data:`STENOSIS_PCT_RANGE`)
and, as the varied suite takes them, a Table-1 geometry
(``TABLE1_CYCLE[(k // 2) % 4]``: the paper's Table 1 and the static pair)
for even k and a random C-arm pair
(:func:`recon.synth.suites.random_geometry`) for odd k. The "tree" suite
renders with the plain renderer; "tree-varied" renders case k with the
imaging chain ``CHAINS[(k // 2) % 6]`` (each chain one Table-1 and one
random pair in 12 cases). Every side branch leaving the main segment is
clicked as a branch. :func:`recon.tree.reconstruct_tree` runs on the
rendered images and header geometry, and is compared with the truth:

- per segment: MLD and reference diameter (the main's as the regular
  suite; a branch's true MLD is the least true diameter from its true
  carina to its distal click, its reference the undiseased taper there),
  and whether the MLD's 95 % interval holds the true MLD
  (``mld_ci95_coverage``, over the segments with an interval).
  ``mld_err_*`` and ``ref_diam_err_*`` are over the segments with a lesion
  (true MLD below :data:`LESION_FRACTION` of its reference: the main
  segment and the narrowed side-branch ostia); a healthy branch's "MLD" is
  only its thinnest, usually distal, stretch, reported apart
  (``mld_err_all_*``, every segment);
- per bifurcation: the bifurcation angle, the three segments' %DS and the
  Medina class, with the definitions of :mod:`recon.lumen.bifurcation` applied to
  the true centerlines, diameters and undiseased tapers (the main vessel
  within the clicked segment, the branch up to its distal click); and the
  branch's sharpest turn (:func:`recon.lumen.bifurcation.sharpest_turn_deg`) from
  the join to :data:`JOIN_TURN_BEYOND_MM` past the carina, against the true
  branch's over the same stretch (a join that kinks the branch shows as an
  excess); whether the tool flagged the branch's origin as implausible
  (``origin_warning``), counted in ``bifurcations_origin_flagged`` with the
  angle error's SD over the others beside the SD over all;
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

from recon.bench.common import parallel_map, pose_error
from recon.errors import CoronaryError
from recon.lumen.bifurcation import (
    MEDINA_DS_PCT,
    BifurcationQCA,
    bifurcation_angles_deg,
    bifurcation_qca,
    carina_s_mm,
    sharpest_turn_deg,
)
from recon.pipeline import ReconstructionOptions
from recon.synth.chains import CHAINS
from recon.synth.presets import PhantomPreset
from recon.synth.suites import TABLE1_CYCLE, random_geometry
from recon.synth.tree import SAMPLE_STEP_MM
from recon.synth.tree_case import TREE_LESIONS, TreeCase, make_tree_case
from recon.tree import reconstruct_tree, tree_calibration
from recon.types import arclength

__all__ = ["run_tree", "format_tree", "tree_jobs", "true_bifurcation", "CASES", "TREE_SUITES"]

CASES = 12  # tree cases when cases is None
#: Each case's lesions narrow the diameter by a percentage drawn from this range (the
#: main lesion and the ostial one alike), so Medina's 50 % threshold falls inside it.
STENOSIS_PCT_RANGE = (35.0, 70.0)
MEDINA_NEAR_PCT = 5.0  # a true %DS this close to Medina's threshold is a borderline class
LESION_FRACTION = 0.75  # a segment "with a lesion": true MLD below this x its reference
JOIN_TURN_BEYOND_MM = 2.0  # the join's turn is measured up to this far past the carina
TREE_SUITES = ("tree", "tree-varied")
BIFURCATION_SEGMENTS = ("proximal_main", "distal_main", "side_branch")


def _taper(r_mm: np.ndarray) -> np.ndarray:
    """The undiseased (linear) taper (N,) of a radius profile sampled every SAMPLE_STEP_MM:
    a phantom lesion is a bump that vanishes at the vessel's ends."""
    t = np.linspace(0.0, 1.0, len(r_mm))
    return r_mm[0] + (r_mm[-1] - r_mm[0]) * t


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
    i = int(np.flatnonzero(inside)[np.argmin(r[inside])])
    return float(2 * r[i]), float(2 * _taper(r)[i])


def true_bifurcation(tc: TreeCase, j: int) -> BifurcationQCA:
    """Bifurcation QCA (:func:`recon.lumen.bifurcation.bifurcation_qca`) of segment j's (j >= 1)
    bifurcation on the true centerlines, diameters and tapers: the main vessel within
    the clicked segment, the branch up to its distal click."""
    truth = tc.case.truth
    main_X, main_r = truth.vessels[0]
    i0 = int(round(truth.segment_start_s_mm / SAMPLE_STEP_MM))
    rows = slice(i0, i0 + len(truth.segment_X_world))
    p_X, p_r, p_ref = main_X[rows], main_r[rows], _taper(main_r)[rows]
    b_X, b_r = truth.vessels[tc.vessels[j]]
    keep = np.arange(len(b_X)) * SAMPLE_STEP_MM <= tc.end_s_mm[j] + 1e-9
    seg = tc.seeds.segments[j]
    return bifurcation_qca(
        seg.bifurcation, seg.parent, seg.name,
        p_X, (arclength(p_X), 2 * p_r, 2 * p_ref),
        b_X[keep], (arclength(b_X[keep]), 2 * b_r[keep], 2 * _taper(b_r)[keep]), 0.0)


def _preset_name(preset: str | PhantomPreset) -> str:
    return preset if isinstance(preset, str) else preset.name


def _case(job: tuple) -> dict:
    preset, seed, lesion, chain, stenosis_pct, *more = job
    tracer = more[0] if more else "2d"
    tc = make_tree_case(preset, seed, lesion, stenosis_pct=stenosis_pct, chain=chain)
    from recon.bench.common import case_angiograms

    a, b = case_angiograms(tc.case)
    t0 = time.perf_counter()
    rec = reconstruct_tree(a, b, tc.seeds, ReconstructionOptions(tracer=tracer))
    wall_ms = (time.perf_counter() - t0) * 1000.0
    truth = tc.case.truth
    segments = []
    for j, branch in enumerate(rec.branches):
        mld_true, ref_true = _branch_truth(tc, j)
        m = branch.measurements
        ci = None if branch.intervals is None else branch.intervals.ci95.get("mld_mm")
        segments.append({
            "name": tc.seeds.segments[j].name,
            "mld_mm": m.mld_mm, "mld_true_mm": mld_true, "mld_error_mm": m.mld_mm - mld_true,
            "reference_diameter_mm": m.reference_diameter_mm,
            "reference_true_mm": ref_true,
            "ref_diam_error_mm": m.reference_diameter_mm - ref_true,
            "diameter_stenosis_pct": m.diameter_stenosis_pct,
            "mld_ci95_mm": None if ci is None else list(ci),
            "mld_ci95_covers": None if ci is None else bool(ci[0] <= mld_true <= ci[1]),
        })
    bifurcations = []
    main_X, main_r = truth.vessels[0]
    for bq in rec.bifurcations:
        j = tc.seeds.segment_index(bq.branch)
        true_X = truth.vessels[tc.vessels[j]][0]
        true_angle, true_prox, info = bifurcation_angles_deg(main_X, main_r, true_X)
        tq = true_bifurcation(tc, j)
        turn = sharpest_turn_deg(rec.branches[j].centerline_3d.X_world,
                                 bq.carina_s_mm + JOIN_TURN_BEYOND_MM)
        turn_true = sharpest_turn_deg(true_X, info["carina_s_mm"] + JOIN_TURN_BEYOND_MM)
        bifurcations.append({
            "name": bq.name, "angle_deg": bq.bifurcation_angle_deg, "angle_true_deg": true_angle,
            "angle_error_deg": bq.bifurcation_angle_deg - true_angle,
            "proximal_angle_error_deg": bq.proximal_angle_deg - true_prox,
            "gap_mm": bq.gap_mm, "join_shift_mm": bq.join_shift_mm,
            "medina": bq.medina, "medina_true": tq.medina,
            "ds_pct": {k: getattr(bq, k).diameter_stenosis_pct for k in BIFURCATION_SEGMENTS},
            "ds_true_pct": {k: getattr(tq, k).diameter_stenosis_pct
                            for k in BIFURCATION_SEGMENTS},
            "join_turn_deg": turn, "join_turn_true_deg": turn_true,
            "origin_flagged": bq.origin_warning is not None,
        })
    X_tree = np.vstack([truth.segment_X_world] + [truth.vessels[v][0] for v in tc.vessels[1:]])
    _, before = pose_error(tc.case.view_b_nominal, tc.case.view_b_true, X_tree)
    _, after = pose_error(rec.first.view_b, tc.case.view_b_true, X_tree)
    scale_free = {key: _scale_free_tree_mm(X_tree, tc.case, view_b) for key, view_b in
                  (("before", tc.case.view_b_nominal), ("after", rec.first.view_b))}
    # the same tree's calibration with the matched points of every branch added
    traced = [(branch.centerline_a, branch.centerline_b) for branch in rec.branches]
    matched = tree_calibration(a, b, tc.seeds, traced,
                               ReconstructionOptions(self_calibration=True))
    _, after_matched = pose_error(matched.view_b, tc.case.view_b_true, X_tree)
    scale_free["after_matched_points"] = _scale_free_tree_mm(X_tree, tc.case, matched.view_b)
    mesh = rec.tree_surface.mesh
    return {
        "preset": _preset_name(preset),
        "chain": chain, "seed": seed, "lesion": lesion, "stenosis_pct": stenosis_pct,
        "segments": segments,
        "bifurcations": bifurcations,
        "pose_displacement_mm_before": before, "pose_displacement_mm_after": after,
        "pose_displacement_mm_after_matched_points": after_matched,
        "scale_free_3d_mm_before": scale_free["before"],
        "scale_free_3d_mm_after": scale_free["after"],
        "scale_free_3d_mm_after_matched_points": scale_free["after_matched_points"],
        "watertight": bool(mesh.is_watertight), "components": rec.tree_surface.components,
        "voxel_mm": rec.tree_surface.voxel_mm, "grid_voxels": rec.tree_surface.grid_voxels,
        "wall_ms": wall_ms,
    }


def _scale_free_tree_mm(X_tree: np.ndarray, case, view_b) -> float:
    """The tree's 3D error (RMS mm) with view B at ``view_b``: the true points (P, 3)
    projected exactly into A and into B's true pose, triangulated with A and ``view_b``,
    after the best scaling about A's source (the baseline's length is unobservable from
    two views), as `bench calibration-modes` measures a segment."""
    from recon.bench.common import scale_free_error_mm
    from recon.geometry import triangulate

    X_rec = triangulate(case.view_a.project(X_tree), case.view_b_true.project(X_tree),
                        case.view_a, view_b)
    return scale_free_error_mm(X_rec, X_tree, case.view_a.source_world)[0]


def tree_jobs(cases: int, seed: int = 0, suite: str = "tree") -> list[tuple]:
    """The suite's cases (module docstring): (preset or random pair, seed, lesion, chain,
    diameter stenosis %)."""
    if suite not in TREE_SUITES:
        raise ValueError(f"unknown tree suite {suite!r} (use one of {', '.join(TREE_SUITES)})")
    chains = list(CHAINS)
    jobs = []
    for k in range(cases):
        preset: str | PhantomPreset
        if k % 2 == 0:
            preset = TABLE1_CYCLE[(k // 2) % len(TABLE1_CYCLE)]
        else:
            preset = random_geometry(np.random.default_rng([int(seed), k, 15]), f"random-{k}")
        chain = chains[(k // 2) % len(chains)] if suite == "tree-varied" else None
        pct = round(float(np.random.default_rng([int(seed), k, 16]).uniform(
            *STENOSIS_PCT_RANGE)), 1)
        jobs.append((preset, seed + k, TREE_LESIONS[k % len(TREE_LESIONS)], chain, pct))
    return jobs


def _case_or_failure(job: tuple) -> tuple[dict | None, dict | None]:
    """(row, None) or (None, failure with its one-line reason) of one case (in a worker)."""
    try:
        return _case(job), None
    except (CoronaryError, ValueError) as err:
        preset, seed, lesion, chain, pct, *_ = job
        return None, {"preset": _preset_name(preset), "chain": chain, "seed": seed,
                      "lesion": lesion, "stenosis_pct": pct,
                      "error": " ".join(str(err).split())}


def run_tree(cases: int | None = None, seed: int = 0, suite: str = "tree",
             tracer: str = "2d") -> dict:
    """Run a tree suite (module docstring); the figures, the rows and the failures.
    ``tracer``: the pipeline's tracer ("2d" or "3d", :data:`recon.pipeline.TRACER_CHOICES`).

    The cases run in up to two worker processes (:func:`recon.bench.common.parallel_map`).
    """
    jobs = [(*job, tracer) for job in tree_jobs(CASES if cases is None else cases, seed, suite)]
    outcomes = parallel_map(_case_or_failure, jobs)
    result = summarise([r for r, _ in outcomes if r is not None],
                       [f for _, f in outcomes if f is not None])
    result["suite"] = suite
    result["tracer"] = tracer
    return result


def _borderline_miss(bif: dict) -> bool:
    """Whether a bifurcation's Medina class differs from the truth's only in segments whose
    true %DS lies within :data:`MEDINA_NEAR_PCT` of the threshold."""
    wrong = [k for k, a, b in zip(BIFURCATION_SEGMENTS, bif["medina"].split(","),
                                  bif["medina_true"].split(","), strict=True) if a != b]
    return bool(wrong) and all(
        abs(bif["ds_true_pct"][k] - MEDINA_DS_PCT) <= MEDINA_NEAR_PCT for k in wrong)


def summarise(rows: list[dict], failed: list[dict]) -> dict:
    """The suite's figures from its case rows (:func:`run_tree`)."""
    segs = [s for r in rows for s in r["segments"]]
    lesion = [s for s in segs if s["mld_true_mm"] < LESION_FRACTION * s["reference_true_mm"]]
    mld_all = np.array([s["mld_error_mm"] for s in segs], dtype=float)
    mld = np.array([s["mld_error_mm"] for s in lesion], dtype=float)
    ref = np.array([s["ref_diam_error_mm"] for s in lesion], dtype=float)
    covered = [s["mld_ci95_covers"] for s in segs if s.get("mld_ci95_covers") is not None]
    covered_lesion = [s["mld_ci95_covers"] for s in lesion
                      if s.get("mld_ci95_covers") is not None]
    bifs = [b for r in rows for b in r["bifurcations"]]
    ang = np.array([b["angle_error_deg"] for b in bifs], dtype=float)
    flagged = np.array([b.get("origin_flagged", False) for b in bifs], dtype=bool)
    gaps = [b["gap_mm"] for b in bifs]
    ds_err = {k: np.array([b["ds_pct"][k] - b["ds_true_pct"][k] for b in bifs], dtype=float)
              for k in BIFURCATION_SEGMENTS}
    turn_excess = np.array([b["join_turn_deg"] - b["join_turn_true_deg"] for b in bifs],
                           dtype=float)

    def mean(v: np.ndarray) -> float | None:
        return float(np.mean(v)) if len(v) else None

    def sd(v: np.ndarray) -> float | None:
        return float(np.std(v, ddof=1)) if len(v) > 1 else None

    def lower(key: str, after: str) -> float | None:
        """The share of cases whose ``key``_``after`` is below ``key``_before."""
        return float(np.mean([r[f"{key}_{after}"] < r[f"{key}_before"] for r in rows])) \
            if rows else None

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
        "mld_ci95_coverage": float(np.mean(covered)) if covered else None,
        "mld_ci95_coverage_lesions": float(np.mean(covered_lesion)) if covered_lesion
        else None,
        "bifurcation_angle_err_mean_deg": mean(ang),
        "bifurcation_angle_err_sd_deg": sd(ang),
        "bifurcations_origin_flagged": int(flagged.sum()),
        "bifurcation_angle_err_sd_deg_unflagged": sd(ang[~flagged]),
        "max_gap_mm": float(max(gaps)) if gaps else None,
        "medina_agreement": float(np.mean([b["medina"] == b["medina_true"] for b in bifs]))
        if bifs else None,
        "medina_disagreements_borderline": sum(_borderline_miss(b) for b in bifs),
        "medina_disagreements": sum(b["medina"] != b["medina_true"] for b in bifs),
        "bifurcation_ds_err_pct": {k: {"mean": mean(v), "sd": sd(v)} for k, v in ds_err.items()},
        "join_turn_excess_deg": {
            "median": float(np.median(turn_excess)) if len(bifs) else None,
            "max": float(np.max(turn_excess)) if len(bifs) else None},
        "pose_better_than_header": lower("pose_displacement_mm", "after"),
        "pose_better_than_header_with_matched_points":
            lower("pose_displacement_mm", "after_matched_points"),
        "pose_better_than_header_scale_free": lower("scale_free_3d_mm", "after"),
        "pose_better_than_header_scale_free_with_matched_points":
            lower("scale_free_3d_mm", "after_matched_points"),
        "scale_free_3d_median_mm": {
            key: float(np.median([r[f"scale_free_3d_mm_{key}"] for r in rows]))
            for key in ("before", "after", "after_matched_points")} if rows else None,
        "pose_displacement_median_mm": {
            key: float(np.median([r[f"pose_displacement_mm_{key}"] for r in rows]))
            for key in ("before", "after", "after_matched_points")} if rows else None,
        "watertight_single_component": float(np.mean(
            [r["watertight"] and r["components"] == 1 for r in rows])) if rows else None,
        "failed": failed,
        "peak_rss_mb": max(resource.getrusage(who).ru_maxrss for who in (
            resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)) / 1024.0,  # one process's
        "rows": rows,
    }


def _pm(v: float | None, fmt: str = "{:+.2f}") -> str:
    return "-" if v is None else fmt.format(v)


def format_tree(result: dict) -> str:
    """Plain-text summary of a :func:`run_tree` result."""
    def f(key: str, fmt: str = "{:+.3f}") -> str:
        v = result.get(key)
        return "-" if v is None else fmt.format(v)

    turn = result["join_turn_excess_deg"]
    sf = result.get("scale_free_3d_median_mm") or {}
    lines = [
        f"Tree suite ({result.get('suite', 'tree')}): {result['cases']} cases "
        f"({result['segments']} segments, "
        f"{result['lesion_segments']} with a lesion, {result['bifurcation_count']} "
        f"bifurcations), {len(result['failed'])} failed",
        f"MLD error mean / SD (mm), lesions   {f('mld_err_mean_mm')} / "
        f"{f('mld_err_sd_mm', '{:.3f}')}",
        f"  every segment                     {f('mld_err_all_mean_mm')} / "
        f"{f('mld_err_all_sd_mm', '{:.3f}')}",
        f"MLD 95 % interval holds the truth   {f('mld_ci95_coverage', '{:.2f}')} of "
        f"segments ({f('mld_ci95_coverage_lesions', '{:.2f}')} of those with a lesion)",
        f"reference diameter error mean / SD  {f('ref_diam_err_mean_mm')} / "
        f"{f('ref_diam_err_sd_mm', '{:.3f}')} mm (lesions)",
        f"bifurcation angle error mean / SD   {f('bifurcation_angle_err_mean_deg', '{:+.2f}')} / "
        f"{f('bifurcation_angle_err_sd_deg', '{:.2f}')} deg",
        f"  origin flagged implausible        {result['bifurcations_origin_flagged']} "
        f"(angle error SD without them "
        f"{f('bifurcation_angle_err_sd_deg_unflagged', '{:.2f}')} deg)",
        f"largest gap at a bifurcation (mm)   {f('max_gap_mm', '{:.3f}')}",
        f"Medina class as the truth's         {f('medina_agreement', '{:.2f}')} "
        f"({result['medina_disagreements']} differ, {result['medina_disagreements_borderline']}"
        f" only where the true %DS is within {MEDINA_NEAR_PCT:.0f} of {MEDINA_DS_PCT:.0f})",
        *[f"  %DS error mean / SD, {k.replace('_', ' '):<13} "
          f"{_pm(v['mean'])} / {_pm(v['sd'], '{:.2f}')}"
          for k, v in result["bifurcation_ds_err_pct"].items()],
        f"join: sharpest turn beyond truth's  median "
        f"{_pm(turn['median'])}, max {_pm(turn['max'])} deg",
        f"pose better than header             {f('pose_better_than_header', '{:.2f}')} "
        f"(with every branch's matched points: "
        f"{f('pose_better_than_header_with_matched_points', '{:.2f}')})",
        f"  3D error lower than header's      {f('pose_better_than_header_scale_free', '{:.2f}')}"
        f" (scale-free RMS, median {sf.get('before', float('nan')):.3f} -> "
        f"{sf.get('after', float('nan')):.3f} mm; with every branch's matched points: "
        f"{f('pose_better_than_header_scale_free_with_matched_points', '{:.2f}')})",
        f"watertight, one component           {f('watertight_single_component', '{:.2f}')}",
        f"peak memory (MB)                    {f('peak_rss_mb', '{:.0f}')}",
    ]
    for fail in result["failed"]:
        chain = f" {fail['chain']}" if fail.get("chain") else ""
        lines.append(f"failed {fail['preset']}-{fail['seed']}{chain} ({fail['lesion']}): "
                     f"{fail['error']}")
    return "\n".join(lines)
