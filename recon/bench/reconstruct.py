"""`coronary3d bench reconstruct`: the whole pipeline against phantom ground truth.

For each synthetic case (the paper's Table 1 geometries and the static
preset, several seeds) the full `reconstruct_pair` runs from the rendered
images, the header geometry and the noisy clicks, and its results are
compared with the truth: 3D centerline error, MLD, % diameter stenosis,
segment length, mesh volume, and the true-pose error of calibrated view B
(:func:`recon.bench.common.pose_error`). The mesh is closed by a cap on each end
(:mod:`recon.lumen.surface`), so its volume is compared with the true segment closed the
same way (:func:`closed_truth_volume_mm3`); the lumen volume between the ends (the
sections' areas integrated along the centerline, no caps) is compared with the true
segment's as ``section_volume_error_pct``.

``suite="varied"`` (:func:`recon.synth.suites.varied_cases`: every imaging
chain x harder anatomy; each image passed as an in-memory angiogram with
the chain's PixelIntensityRelationship tag and bits stored) reports the
same end-to-end figures per chain and overall: median and 90th percentile
|MLD error|, median |length error| and |mesh volume error|, the 3D
centerline RMS after a rigid (rotation + translation, not scaled)
alignment to the truth (median and max), and the failed cases with their
one-line reason. It also judges the two traces each reconstruction rests on as
``bench centerline`` judges a trace (``trace_success``), and counts the lost ones
the cross-view check did not flag (``traces_lost_unflagged``: wrong without a sign).

``suite="tree"`` and ``"tree-varied"``: phantom trees with bifurcation lesions,
every branch in one reconstruction, the second through the imaging chains
(:mod:`recon.bench.tree`).

``jitter=N`` adds click stability: per case, N more runs with every click
moved uniformly within a disc of :data:`JITTER_PX`; the spread (max - min
over the N runs) of the MLD, the %DS and the MLD site (mm along the 3D
centerline), and the fraction of cases with an MLD spread of at most
:data:`STABLE_MLD_SPREAD_MM` and a site spread of at most
:data:`STABLE_SITE_SPREAD_MM` (a case with a failed run is not stable).
``lesion_set_stable`` is the fraction of cases whose set of lesions
(:mod:`recon.lumen.lesions`: every narrowing that passes the lesion criterion,
tandems less than 3 reference diameters apart merged into one lesion) is the same in
the base run and all N jittered runs (:func:`recon.lumen.lesions.lesion_sets_equal`,
rule "overlap": as many, paired proximal to distal, each pair's extents overlapping;
a case with a failed run is not stable). Issue 46's second pass changed what it
compares (before: every narrowing past the floor its own lesion, paired by each one's
MLD inside the other's extent); ``lesion_set_stable_unmerged`` keeps that comparison
(rule "mld", no tandem merge) on the same runs, so the two figures stand side by side.
``lesion_set_stable_delta`` is ``lesion_set_stable`` had every narrowing of at least
the disease threshold delta been a lesion (no % stenosis floor), to show what the
floor buys; ``lesion_set_stable_completed`` is ``lesion_set_stable`` over the cases
whose runs all ran (a refused jittered trace leaves no lesion set to compare). The
borderline narrowings (below the floor, their interval reaching it) are listed per
run in ``borderline_sets`` and are not lesions. ``lesion_set_kept_or_borderline`` is
a looser figure, not the target's: the share of cases in which no lesion of any run
is missing from another without a word
(:func:`recon.lumen.lesions.lesions_kept_or_borderline`: a lesion of one run may be a
borderline narrowing at the same place in another; a failed run is not kept); it shows
what the borderline list buys.
"""

from __future__ import annotations

import time

import numpy as np

from recon.bench.common import (
    PRESET_CYCLE,
    VARIED_CASES_PER_CHAIN,
    case_angiograms,
    check_suite,
    jitter_seeds,
    median,
    parallel_map,
    percentile,
    polyline_distance_mm,
    pose_error,
    rigid_rms_mm,
    scale_free_rms_mm,
    varied_rows,
)
from recon.lumen.lesions import lesion_sets_equal, lesions_kept_or_borderline
from recon.pipeline import Reconstruction, ReconstructionOptions, reconstruct_pair
from recon.synth import PhantomCase, PhantomTruth, make_phantom

CASES = 8  # phantom cases when run(cases=None)
STENOSIS_PCT = 50.0  # diameter stenosis of every case
SELF_CALIBRATION = False  # ReconstructionOptions.self_calibration of the runs
JITTER_PX = 2.0  # click stability: every click moves up to this far (uniform in a disc)
STABLE_MLD_SPREAD_MM = 0.1
STABLE_SITE_SPREAD_MM = 2.0
RIGID_RMS_LIMIT_MM = 0.6  # the target: no case above this after a rigid alignment


def evaluate_case(case: PhantomCase, options: ReconstructionOptions, *,
                  rigid: bool = False) -> dict:
    """One case's end-to-end figures (``rigid``: also the RMS after a rigid alignment)."""
    a, b = case_angiograms(case)
    t0 = time.perf_counter()
    rec = reconstruct_pair(a, b, case.seeds, options)
    wall_ms = (time.perf_counter() - t0) * 1000.0
    row = _case_row(case, rec, wall_ms)
    if rigid:
        row["centerline_3d_rms_rigid_mm"] = rigid_rms_mm(rec.centerline_3d.X_world,
                                                         case.truth.segment_X_world)
        row["mld_s_mm"] = float(rec.measurements.mld_s_mm)
        consistency = getattr(rec, "consistency", None)
        row["consistency_ok"] = None if consistency is None else bool(consistency.ok)
        row["flagged_stretches"] = 0 if consistency is None else len(consistency.stretches)
        row["warnings"] = list(getattr(rec, "warnings", ()))
        row["lesion_sets"] = _lesion_sets(rec)
        row.update(_trace_figures(case, rec))
        row["mappings"] = [getattr(rec.centerline_a, "intensity_mapping", None),
                           getattr(rec.centerline_b, "intensity_mapping", None)]
    return row


def _trace_figures(case: PhantomCase, rec: Reconstruction) -> dict:
    """Whether each view's final trace (the one the 3D result rests on) lies on the
    projected true segment (``bench centerline``'s criterion: no stretch more than
    :data:`~recon.bench.centerline.SUCCESS_PX` off), and whether a lost trace was told:
    the cross-view check listed a stretch of that view (``trace_lost_unflagged_a|b`` is
    a trace lost without any sign to the user)."""
    from recon.bench.centerline import SUCCESS_PX, truth_gap_px

    out: dict = {}
    consistency = rec.consistency
    for name, cl, view in (("a", rec.centerline_a, case.view_a),
                           ("b", rec.centerline_b, case.view_b_true)):
        gap, _ = truth_gap_px(cl.points_px, view, case.truth)
        lost = bool(np.any(gap > SUCCESS_PX))
        flagged = consistency is not None and any(st.view == name
                                                  for st in consistency.stretches)
        out[f"trace_gap_px_{name}"] = float(gap.max()) if len(gap) else 0.0
        out[f"trace_lost_{name}"] = lost
        out[f"trace_lost_unflagged_{name}"] = lost and not flagged
    return out


#: The lesion-set stability figures: (key, which set of :func:`_lesion_sets`, rule).
LESION_SET_FIGURES = (("lesion_set_stable", "lesions", "overlap"),
                      ("lesion_set_stable_delta", "delta", "overlap"),
                      ("lesion_set_stable_unmerged", "unmerged", "mld"))


def _lesion_sets(rec: Reconstruction) -> dict[str, list[dict]]:
    """The run's lesions (their sites, extents and %DS; tandems merged), those it would
    have with every supported narrowing of at least delta a lesion (no % stenosis floor;
    tandems merged), every supported narrowing past the floor on its own (no merge:
    the comparison before issue 46's second pass) and the borderline narrowings."""
    from recon.lumen.measure import lesions_of, narrowings

    def brief(n) -> dict:
        return {"mld_s_mm": round(n.mld_s_mm, 2), "start_s_mm": round(n.start_s_mm, 2),
                "end_s_mm": round(n.end_s_mm, 2),
                "diameter_stenosis_pct": round(n.diameter_stenosis_pct, 1)}

    report = rec.lesions
    return {"lesions": [brief(les.narrowing) for les in report.lesions],
            "delta": [brief(n) for n in lesions_of(rec.profile, min_ds_pct=0.0)],
            "unmerged": [brief(n) for n in narrowings(rec.profile) if n.supported],
            "borderline": [brief(b.narrowing) for b in report.borderline]}


def closed_truth_volume_mm3(truth: PhantomTruth) -> float:
    """The true segment's volume closed as the mesh is closed: its lumen volume
    (pi * integral r^2 ds) plus a hemisphere on each end section, the half-ellipsoid
    caps of :mod:`recon.lumen.surface` for a round lumen (mm^3)."""
    r = truth.segment_radius_mm
    return float(truth.segment_volume_mm3 + 2.0 / 3.0 * np.pi * (r[0] ** 3 + r[-1] ** 3))


def section_volume_mm3(rec: Reconstruction) -> float:
    """The reconstruction's lumen volume between its ends, without the caps: the
    integral of the elliptic sections' areas along the 3D centerline (mm^3)."""
    return float(np.trapezoid(rec.surface.sections.area_mm2, rec.centerline_3d.s_mm))


def _error_pct(value: float, true: float) -> float:
    """Signed error of ``value`` in per cent of ``true``."""
    return 100.0 * (value - true) / true


def _case_row(case: PhantomCase, rec, wall_ms: float) -> dict:
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
        "length_error_pct": _error_pct(m.segment_length_mm, true_length),
        "lesion_length_mm": m.lesion_length_mm,
        "lesion_length_true_mm": truth.stenosis_length_mm,
        "volume_error_pct": _error_pct(float(rec.surface.mesh.volume),
                                      closed_truth_volume_mm3(truth)),
        "section_volume_error_pct": _error_pct(section_volume_mm3(rec), truth.segment_volume_mm3),
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


def run(cases: int | None = None, seed: int = 0, suite: str = "regular",
        jitter: int = 0, workers: int | None = None, tracer: str = "2d") -> dict:
    """Run the end-to-end benchmark on ``cases`` phantom cases; medians and rows.

    ``cases`` None means :data:`CASES`; case k is preset ``PRESET_CYCLE[k % 4]``
    with seed ``seed + k``. ``suite="varied"``: ``cases`` per imaging chain
    (None: 8), figures per chain and overall (module docstring). ``jitter``:
    that many extra runs per case with jittered clicks, reported under
    "stability". ``workers``: the regular suite's cases run as tasks on a
    local Dask cluster of that many processes (the engine of `coronary3d
    batch`); None runs them one after another in this process. ``tracer``: the
    pipeline's tracer ("2d" or "3d", :data:`recon.pipeline.TRACER_CHOICES`).
    """
    check_suite(suite)
    if jitter < 0:
        raise ValueError(f"jitter must be >= 0, got {jitter}")
    if suite == "varied":
        return _run_varied(VARIED_CASES_PER_CHAIN if cases is None else cases, seed, jitter,
                           tracer)
    result = _run_regular(cases, seed, workers, tracer)
    if jitter:
        cases = CASES if cases is None else cases
        jobs = [(("regular", PRESET_CYCLE[k % len(PRESET_CYCLE)], seed + k), jitter)
                for k in range(cases)]
        result["stability"] = _stability_summary([o["stability"] for o in
                                                  parallel_map(_case_job, jobs)])
    return result


def _regular_case(job: tuple[str, int, str]) -> tuple[dict | None, dict | None]:
    """One regular-suite case: (row, None), or (None, failure) (runs in a worker)."""
    preset, case_seed, tracer = job
    case = make_phantom(preset, case_seed, stenosis_pct=STENOSIS_PCT)
    try:
        return evaluate_case(case, ReconstructionOptions(self_calibration=SELF_CALIBRATION,
                                                         tracer=tracer)), None
    except ValueError as err:  # a failed case is a result, not a crash of the bench
        return None, {"preset": preset, "seed": case_seed, "error": str(err)}


def _run_regular(cases: int | None, seed: int, workers: int | None = None,
                 tracer: str = "2d") -> dict:
    cases = CASES if cases is None else cases
    self_calibration = SELF_CALIBRATION
    jobs = [(PRESET_CYCLE[k % len(PRESET_CYCLE)], seed + k, tracer) for k in range(cases)]
    t0 = time.perf_counter()
    if workers is None:
        outcomes = [_regular_case(job) for job in jobs]
    else:
        from recon.io.engine import map_ordered

        outcomes = map_ordered(_regular_case, jobs, workers=workers)
    elapsed_s = time.perf_counter() - t0
    rows = [row for row, _ in outcomes if row is not None]
    failures = [failure for _, failure in outcomes if failure is not None]
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
        "tracer": tracer,
        "centerline_3d_rms_mm": med("centerline_3d_rms_mm"),
        "centerline_3d_rms_scale_free_mm": med("centerline_3d_rms_scale_free_mm"),
        "abs_mld_error_mm": med("mld_error_mm", absolute=True),
        "abs_diameter_stenosis_error_pct": med("diameter_stenosis_error_pct", absolute=True),
        "abs_length_error_pct": med("length_error_pct", absolute=True),
        "abs_volume_error_pct": med("volume_error_pct", absolute=True),
        "abs_section_volume_error_pct": med("section_volume_error_pct", absolute=True),
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
        "workers": workers,
        "cases_per_minute": 60.0 * cases / elapsed_s,
        "median_stage_ms": {
            s: float(np.median([r["timings_ms"].get(s, 0.0) for r in rows])) for s in stages
        },
        "rows": rows,
    }


def format_table(result: dict) -> str:
    """Plain-text table of a :func:`run` result."""
    if result.get("suite") == "varied":
        return _format_varied(result)
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
        f"median |lumen volume error|     {result['abs_section_volume_error_pct']:.1f} % "
        "(sections between the ends, no caps)",
        f"watertight meshes               {result['watertight_rate'] * 100:.0f} %",
        f"pose better than header         {result['pose_improved_rate'] * 100:.0f} %",
        f"median pipeline time            {result['median_pipeline_ms']:.0f} ms "
        + ", ".join(f"{k} {v:.0f}" for k, v in result["median_stage_ms"].items()),
        f"failed cases                    {len(result.get('failures', []))}",
    ]
    if result.get("cases_per_minute") is not None:
        where = (f"{result['workers']} Dask worker(s)" if result.get("workers")
                 else "one process")
        lines.append(f"throughput                      {result['cases_per_minute']:.1f} "
                     f"cases per minute on {where}")
    if result.get("stability"):
        lines += _format_stability(result["stability"])
    return "\n".join(lines)


# ------------------------------------------------------------------ varied suite
def _make(which) -> tuple[PhantomCase, dict]:
    """The case of a job and the keys that name it in the rows."""
    if which[0] == "regular":
        _, preset, case_seed = which
        case = make_phantom(preset, case_seed, stenosis_pct=STENOSIS_PCT)
        return case, {"chain": "regular", "preset": preset, "seed": case_seed,
                      "anatomy": "plain"}
    from recon.synth.suites import make_suite_case

    spec = which[1]
    case = make_suite_case(spec, stenosis_pct=STENOSIS_PCT)
    return case, {"chain": spec.chain, "preset": spec.preset_name, "seed": spec.seed,
                  "anatomy": spec.anatomy}


def _one_line(err: BaseException) -> str:
    return f"{type(err).__name__}: " + " ".join(str(err).split())


def _case_job(job) -> dict:
    """One case: the base run and ``jitter`` runs with jittered clicks (runs in a worker)."""
    which, jitter, *more = job
    options = ReconstructionOptions(self_calibration=SELF_CALIBRATION,
                                    tracer=more[0] if more else "2d")
    case, key = _make(which)
    out: dict = {"key": key, "row": None, "failure": None, "stability": None}
    try:
        out["row"] = {**key, **evaluate_case(case, options, rigid=True)}
    except ValueError as err:  # CoronaryError included: a failed case is a result
        out["failure"] = {**key, "error": _one_line(err)}
    if jitter:
        out["stability"] = {**key, **_jitter_case(case, options, jitter, out["row"])}
    return out


def _jitter_case(case: PhantomCase, options: ReconstructionOptions, n: int,
                 base: dict | None) -> dict:
    """Spreads of MLD, %DS and MLD site over ``n`` runs with every click jittered."""
    a, b = case_angiograms(case)
    rng = np.random.default_rng([case.seed, 7919, n])
    mld, ds, site, errors = [], [], [], []
    sets = [] if base is None else [base["lesion_sets"]]
    for _ in range(n):
        seeds = jitter_seeds(case.seeds, rng, JITTER_PX, a.shape, b.shape)
        try:
            rec = reconstruct_pair(a, b, seeds, options)
        except ValueError as err:
            errors.append(_one_line(err))
            continue
        m = rec.measurements
        mld.append(m.mld_mm)
        ds.append(m.diameter_stenosis_pct)
        site.append(m.mld_s_mm)
        sets.append(_lesion_sets(rec))

    def spread(v: list[float]) -> float:
        return float(np.ptp(v)) if v else float("nan")

    out = {
        "runs": len(mld),
        "failed_runs": len(errors),
        "errors": errors[:3],
        "base_failed": base is None,
        "mld_spread_mm": spread(mld),
        "ds_spread_pct": spread(ds),
        "site_spread_mm": spread(site),
        "mld_mm": [float(x) for x in mld],
        "ds_pct": [float(x) for x in ds],
        "site_mm": [float(x) for x in site],
    }
    all_ran = not errors and bool(mld)
    out["mld_stable"] = bool(all_ran and out["mld_spread_mm"] <= STABLE_MLD_SPREAD_MM)
    out["site_stable"] = bool(all_ran and out["site_spread_mm"] <= STABLE_SITE_SPREAD_MM)
    out["stable"] = out["mld_stable"] and out["site_stable"]
    out["lesion_counts"] = [len(one["lesions"]) for one in sets]
    for which in ("lesions", "delta", "unmerged", "borderline"):
        out["lesion_sets" if which == "lesions" else f"{which}_sets"] = [one[which]
                                                                         for one in sets]
    for key, which, rule in LESION_SET_FIGURES:
        out[key] = bool(all_ran and base is not None
                        and all(lesion_sets_equal(sets[0][which], other[which], rule)
                                for other in sets[1:]))
    out["lesion_set_kept_or_borderline"] = bool(
        all_ran and base is not None
        and all(lesions_kept_or_borderline(x["lesions"], y["lesions"], x["borderline"],
                                           y["borderline"])
                for i, x in enumerate(sets) for y in sets[i + 1:]))
    return out


def _stability_figures(cases: list[dict]) -> dict:
    return {
        "cases": len(cases),
        "stable_fraction": float(np.mean([c["stable"] for c in cases])) if cases else float("nan"),
        "mld_within_fraction": float(np.mean([c["mld_stable"] for c in cases])) if cases
        else float("nan"),
        "site_within_fraction": float(np.mean([c["site_stable"] for c in cases])) if cases
        else float("nan"),
        "cases_with_failed_runs": sum(c["failed_runs"] > 0 or c["runs"] == 0 for c in cases),
        "mld_spread_mm_median": median(c["mld_spread_mm"] for c in cases),
        "mld_spread_mm_max": percentile([c["mld_spread_mm"] for c in cases], 100),
        "ds_spread_pct_median": median(c["ds_spread_pct"] for c in cases),
        "ds_spread_pct_max": percentile([c["ds_spread_pct"] for c in cases], 100),
        "site_spread_mm_median": median(c["site_spread_mm"] for c in cases),
        "site_spread_mm_max": percentile([c["site_spread_mm"] for c in cases], 100),
        **{key: _fraction(cases, key) for key, _, _ in LESION_SET_FIGURES},
        "lesion_set_kept_or_borderline": _fraction(cases, "lesion_set_kept_or_borderline"),
        # the same over the cases whose runs all ran (a refused trace has no lesion set)
        "lesion_set_stable_completed": _fraction(
            [c for c in cases if c["failed_runs"] == 0 and not c["base_failed"]],
            "lesion_set_stable"),
        "lesions_per_run_median": median(n for c in cases for n in c.get("lesion_counts", [])),
    }


def _fraction(cases: list[dict], key: str) -> float:
    """Share of ``cases`` with ``key`` true (NaN for none)."""
    return float(np.mean([bool(c.get(key)) for c in cases])) if cases else float("nan")


def _stability_summary(cases: list[dict]) -> dict:
    chains = {name: _stability_figures([c for c in cases if c["chain"] == name])
              for name in dict.fromkeys(c["chain"] for c in cases)}
    runs = max((c["runs"] + c["failed_runs"] for c in cases), default=0)
    return {
        "jitter_runs": runs,
        "jitter_px": JITTER_PX,
        "criteria": {"mld_spread_mm": STABLE_MLD_SPREAD_MM,
                     "site_spread_mm": STABLE_SITE_SPREAD_MM},
        "target_stable_fraction": 0.9,
        "target_lesion_set_stable": 0.9,
        "overall": _stability_figures(cases),
        "chains": chains,
        "cases": cases,
    }


def _figures(rows: list[dict], failures: list[dict]) -> dict:
    """End-to-end figures of a set of varied-suite cases (rows ran, failures did not)."""
    def col(key: str, absolute: bool = True) -> list[float]:
        return [abs(r[key]) if absolute else r[key] for r in rows]

    rigid = col("centerline_3d_rms_rigid_mm")
    return {
        "cases": len(rows) + len(failures),
        "succeeded": len(rows),
        "failed": len(failures),
        "abs_mld_error_mm": median(col("mld_error_mm")),
        "p90_abs_mld_error_mm": percentile(col("mld_error_mm"), 90),
        "max_abs_mld_error_mm": percentile(col("mld_error_mm"), 100),
        "abs_diameter_stenosis_error_pct": median(col("diameter_stenosis_error_pct")),
        "abs_length_error_pct": median(col("length_error_pct")),
        "abs_volume_error_pct": median(col("volume_error_pct")),
        "abs_section_volume_error_pct": median(col("section_volume_error_pct")),
        "centerline_3d_rms_rigid_mm": median(rigid),
        "max_centerline_3d_rms_rigid_mm": percentile(rigid, 100),
        "cases_above_rigid_limit": sum(x > RIGID_RMS_LIMIT_MM for x in rigid),
        "centerline_3d_rms_mm": median(col("centerline_3d_rms_mm")),
        "centerline_3d_rms_scale_free_mm": median(col("centerline_3d_rms_scale_free_mm")),
        "watertight_rate": float(np.mean([r["watertight"] for r in rows])) if rows
        else float("nan"),
        "pose_improved_rate": float(np.mean([r["pose_displacement_mm_after"]
                                             < r["pose_displacement_mm_before"] for r in rows]))
        if rows else float("nan"),
        "median_pipeline_ms": median(col("wall_ms")),
        "flagged_cases": sum(r.get("flagged_stretches", 0) > 0 for r in rows),
        # the reconstructed cases' final traces (both views): on the truth, and the lost
        # ones the cross-view check did not flag (wrong without a sign)
        "trace_success": float(np.mean([not r[f"trace_lost_{v}"] for r in rows for v in "ab"]))
        if rows else float("nan"),
        "traces_lost_unflagged": sum(r[f"trace_lost_unflagged_{v}"] for r in rows for v in "ab"),
        "failures": [{k: f[k] for k in ("preset", "seed", "anatomy", "error")} for f in failures],
    }


def _run_varied(per_chain: int, seed: int, jitter: int, tracer: str = "2d") -> dict:
    from recon.synth.suites import varied_cases

    specs = varied_cases(per_chain, seed)
    t0 = time.perf_counter()
    outs = parallel_map(_case_job, [(("varied", spec), jitter, tracer) for spec in specs])
    rows = [o["row"] for o in outs if o["row"] is not None]
    failures = [o["failure"] for o in outs if o["failure"] is not None]

    def group(key: str) -> dict[str, dict]:
        names = dict.fromkeys(o["key"][key] for o in outs)
        return {n: _figures([r for r in rows if r[key] == n],
                            [f for f in failures if f[key] == n]) for n in names}

    result = {
        "suite": "varied",
        "cases": len(specs),
        "cases_per_chain": int(per_chain),
        "seed": int(seed),
        "self_calibration": SELF_CALIBRATION,
        "tracer": tracer,
        "stenosis_pct": STENOSIS_PCT,
        "chains": group("chain"),
        "overall": _figures(rows, failures),
        "anatomy": group("anatomy"),
        "targets": {"abs_mld_error_mm": 0.08, "p90_abs_mld_error_mm": 0.2,
                    "abs_length_error_pct": 1.0, "abs_volume_error_pct": 4.0,
                    "max_centerline_3d_rms_rigid_mm": RIGID_RMS_LIMIT_MM},
        "rows": rows,
        "failures": failures,
    }
    if jitter:
        result["stability"] = _stability_summary([o["stability"] for o in outs])
    result["wall_s"] = time.perf_counter() - t0
    return result


def _format_varied(result: dict) -> str:
    head = (f"{'':<22}{'cases':>6}{'fail':>5}{'|MLD| mm':>9}{'p90':>7}{'|%DS|':>7}"
            f"{'|len| %':>8}{'|vol| %':>8}{'rigid mm':>9}{'max':>7}{'>0.6':>5}{'flag':>5}"
            f"{'trace':>7}{'silent':>7}{'ms':>7}")
    lines = [f"End-to-end reconstruction, varied suite ({result['cases_per_chain']} cases per "
             f"chain, seed {result['seed']}; medians unless noted)", head, "-" * len(head)]

    def line(name: str, f: dict) -> str:
        return (f"{name:<22}{f['cases']:>6}{f['failed']:>5}{f['abs_mld_error_mm']:>9.3f}"
                f"{f['p90_abs_mld_error_mm']:>7.3f}{f['abs_diameter_stenosis_error_pct']:>7.1f}"
                f"{f['abs_length_error_pct']:>8.2f}{f['abs_volume_error_pct']:>8.1f}"
                f"{f['centerline_3d_rms_rigid_mm']:>9.3f}"
                f"{f['max_centerline_3d_rms_rigid_mm']:>7.2f}{f['cases_above_rigid_limit']:>5}"
                f"{f['flagged_cases']:>5}{f['trace_success']:>7.2f}{f['traces_lost_unflagged']:>7}"
                f"{f['median_pipeline_ms']:>7.0f}")

    lines += varied_rows(result, line, "-" * len(head))
    for f in result["failures"]:
        lines.append(f"FAILED {f['chain']} {f['preset']}/{f['seed']} {f['anatomy']}: {f['error']}")
    if result.get("stability"):
        lines += _format_stability(result["stability"])
    t = result["targets"]
    lines.append("")
    lines.append(f"targets: |MLD| <= {t['abs_mld_error_mm']} mm (p90 <= "
                 f"{t['p90_abs_mld_error_mm']}), |length| <= {t['abs_length_error_pct']} %, "
                 f"|volume| <= {t['abs_volume_error_pct']} %, no case above "
                 f"{t['max_centerline_3d_rms_rigid_mm']} mm rigid RMS; stability >= 0.9")
    lines.append("fail: the run raised (counted, with its reason above); flag: ran, but the "
                 "cross-view check listed stretches; rigid: 3D RMS after a rigid alignment")
    lines.append("trace: the final traces of the cases that ran (both views) within "
                 "2 px of the projected truth; silent: traces lost that no flag named")
    lines.append(f"{result['wall_s']:.0f} s wall")
    return "\n".join(lines)


def _format_stability(st: dict) -> list[str]:
    lines = ["", f"click stability: {st['jitter_runs']} runs per case, every click moved "
             f"up to {st['jitter_px']:g} px (spreads: max - min; medians unless 'max')",
             f"{'':<22}{'cases':>6}{'stable':>8}{'MLD<=0.1':>9}{'site<=2':>8}"
             f"{'MLD spr':>8}{'max':>7}{'%DS spr':>8}{'site spr':>9}{'max':>7}{'fail':>5}"
             f"{'lesions':>8}{'(delta)':>8}{'(old)':>6}"]
    for name, f in [*st["chains"].items(), ("overall", st["overall"])]:
        lines.append(
            f"{name:<22}{f['cases']:>6}{f['stable_fraction']:>8.2f}"
            f"{f['mld_within_fraction']:>9.2f}{f['site_within_fraction']:>8.2f}"
            f"{f['mld_spread_mm_median']:>8.3f}{f['mld_spread_mm_max']:>7.2f}"
            f"{f['ds_spread_pct_median']:>8.1f}{f['site_spread_mm_median']:>9.2f}"
            f"{f['site_spread_mm_max']:>7.1f}{f['cases_with_failed_runs']:>5}"
            f"{f['lesion_set_stable']:>8.2f}{f['lesion_set_stable_delta']:>8.2f}"
            f"{f['lesion_set_stable_unmerged']:>6.2f}")
    lines.append("lesions: the share of cases whose set of lesions is the same in every run "
                 "(delta: had every narrowing past the disease threshold been a lesion; old: "
                 "every narrowing past the floor its own lesion, paired by MLD site)")
    return lines
