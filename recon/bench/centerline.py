"""`coronary3d bench centerline`: 2D tracing against the phantom's projected truth.

For each synthetic case (several presets and seeds) and each view (A, and B
with its TRUE geometry), the segment is traced from the phantom's noisy clicks
and compared with the true projected main vessel:

- centerline_rms_px: RMS distance from every traced point to the nearest
  point of the true projected centerline of the main vessel (densely
  resampled to 0.02 px, so the discretisation error is negligible);
- radius_mae_px: mean |traced radius - true radius| where the true radius is
  r_mm SID / depth / spacing at the nearest true point; the first and last
  3 px of arc length of the trace are excluded (the profile there may reach
  past the clicked end);
- vesselness_ms: time of :func:`compute_vesselness` on one whole image;
- trace_ms: time of :func:`trace_segment` for the segment, given the vesselness.

Summary figures are medians over cases and both views.

``suite="varied"`` (:func:`recon.synth.suites.varied_cases`: every imaging
chain x harder anatomy) reports per chain and overall, with each image
passed as the chain's file would be (its PixelIntensityRelationship tag and
the pixel size at the isocenter) and traced as the pipeline traces one view
(the intensity mapping resolved on the whole image, then
:func:`trace_segment`; trace_ms includes the mapping's resolution):

- trace_success: the fraction of traces with no stretch of the projected
  true segment more than :data:`SUCCESS_PX` from the trace (the first and
  last 3 px of the truth left out: the clicked ends carry click noise); a
  trace the tool refuses (TraceError) counts as a failure, not as skipped;
- centerline_rms_px, radius_mae_px: as above, medians over the traces the
  tool returned;
- radius_bias_pct: median over those traces of the mean signed
  100 (fitted - true) / true radius, without the first and last 3 px;
- trace_success_answered: the same after a simulated clinician answers the tool's
  refusals: a refusal that names a place gets a waypoint clicked on the projected
  true segment nearest it, and the segment is traced again (at most
  :data:`ANSWER_ROUNDS` waypoints a trace); a trace lost without a refusal stays
  lost (nothing told the clinician where to look);
- click_error_px, snap_error_px: median, 90th percentile and fraction above
  :data:`SUCCESS_PX` of every click's distance to the projected true segment,
  as clicked and after :func:`snap_click` (as :func:`trace_segment` snaps it),
  over all traces, refused ones included: whether snapping moves the phantom's
  clicks nearer the true centre line or away from it.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from recon.bench.common import (
    PRESET_CYCLE,
    VARIED_CASES_PER_CHAIN,
    case_angiogram,
    check_suite,
    median,
    parallel_map,
    percentile,
    varied_rows,
)
from recon.geometry import ViewGeometry
from recon.synth import PhantomTruth, make_phantom
from recon.trace.centerline import (
    VesselnessMap,
    compute_vesselness,
    snap_click,
    trace_segment,
)
from recon.trace.guide_catheter import find_catheters
from recon.types import arclength

__all__ = ["run", "format_table", "PRESET_CYCLE", "END_EXCLUSION_PX", "CASES", "SUCCESS_PX",
           "truth_gap_px"]

CASES = 10  # phantom cases when run(cases=None)
#: Arc length (px) left out of the radius error at both ends of each trace.
END_EXCLUSION_PX = 3.0
#: A trace succeeds when no point of the projected true segment is farther than this (px).
SUCCESS_PX = 2.0
#: Refusals a simulated clinician answers with a waypoint where the tool asks, per trace.
ANSWER_ROUNDS = 2
#: The phantom's catheter counts as shown in a view when this much of it (mm) projects
#: inside the field.
CATHETER_MIN_VISIBLE_MM = 20.0


def _dense_truth(
    view: ViewGeometry, X_world: np.ndarray, radius_mm: np.ndarray, step_px: float = 0.02
) -> tuple[np.ndarray, np.ndarray]:
    """True projected centerline (M, 2) resampled every ``step_px``, and radius (M,) px."""
    pts = view.project(X_world)
    depth = view.depth_mm(X_world)
    radius_px = radius_mm * view.sid_mm / depth / float(np.mean(view.pixel_spacing_mm))
    s = arclength(pts)
    s_new = np.arange(0.0, s[-1], step_px)
    dense = np.column_stack([np.interp(s_new, s, pts[:, 0]), np.interp(s_new, s, pts[:, 1])])
    return dense, np.interp(s_new, s, radius_px)


def _evaluate_view(
    image: np.ndarray, view: ViewGeometry, clicks_px: np.ndarray, truth_X: np.ndarray,
    truth_r_mm: np.ndarray, name: str,
) -> dict:
    t0 = time.perf_counter()
    vmap = compute_vesselness(image)
    t1 = time.perf_counter()
    cl = trace_segment(image, clicks_px, vesselness=vmap, view=name)
    t2 = time.perf_counter()
    dense, radius_true = _dense_truth(view, truth_X, truth_r_mm)
    dist, nearest = cKDTree(dense).query(cl.points_px)
    s = cl.arclength_px
    inner = (s >= END_EXCLUSION_PX) & (s <= s[-1] - END_EXCLUSION_PX)
    err_r = cl.radius_px[inner] - radius_true[nearest[inner]]
    return {
        "view": name,
        "n_points": int(len(cl.points_px)),
        "length_px": float(cl.length_px),
        "centerline_rms_px": float(np.sqrt(np.mean(dist**2))),
        "centerline_max_px": float(dist.max()),
        "radius_mae_px": float(np.mean(np.abs(err_r))),
        "radius_bias_px": float(np.mean(err_r)),
        "radius_true_median_px": float(np.median(radius_true[nearest])),
        "vesselness_ms": 1e3 * (t1 - t0),
        "trace_ms": 1e3 * (t2 - t1),
    }


def run(cases: int | None = None, seed: int = 0, suite: str = "regular") -> dict:
    """Trace the phantom segment in both views of ``cases`` cases.

    Parameters
    ----------
    cases : number of phantom cases (None: :data:`CASES`); presets cycle
        through :data:`PRESET_CYCLE`. For the varied suite: cases per chain
        (None: 8).
    seed : seed of the first case (case k uses seed + k).
    suite : "regular" (the plain phantom) or "varied" (imaging chains x
        harder anatomy; see the module docstring).

    Returns
    -------
    dict with "cases", the medians "centerline_rms_px", "radius_mae_px",
    "vesselness_ms", "trace_ms" (over cases and both views), "rows" (one per
    case and view), "failures" (traces that raised) and "notes". The varied
    suite's dict has "suite", "chains" {name: figures}, "overall" (the same
    figures over all traces), "rows" and "failures".
    """
    check_suite(suite)
    if suite == "varied":
        return _run_varied(VARIED_CASES_PER_CHAIN if cases is None else cases, seed)
    cases = CASES if cases is None else cases
    rows: list[dict] = []
    failures: list[dict] = []
    for k in range(cases):
        preset = PRESET_CYCLE[k % len(PRESET_CYCLE)]
        case = make_phantom(preset, seed + k, render=True)
        segment = case.seeds.segments[0]
        main_X, main_r = case.truth.vessels[0]  # the whole main vessel: traces may run past
        for name, image, view, clicks in (
            ("A", case.image_a, case.view_a, segment.a),
            ("B", case.image_b, case.view_b_true, segment.b),
        ):
            try:
                row = _evaluate_view(image, view, clicks, main_X, main_r, name)
            except ValueError as err:
                failures.append({"preset": preset, "seed": seed + k, "view": name,
                                 "error": str(err)})
                continue
            rows.append({"preset": preset, "seed": seed + k, **row})

    def med(key: str) -> float:
        return float(np.median([r[key] for r in rows])) if rows else float("nan")

    return {
        "cases": int(cases),
        "traces": len(rows),
        "centerline_rms_px": med("centerline_rms_px"),
        "radius_mae_px": med("radius_mae_px"),
        "radius_bias_px": med("radius_bias_px"),
        "vesselness_ms": med("vesselness_ms"),
        "trace_ms": med("trace_ms"),
        "targets": {"centerline_rms_px": 0.3, "radius_mae_px": 0.3,
                    "vesselness_ms": 500.0, "trace_ms": 50.0},
        "rows": rows,
        "failures": failures,
        "notes": (
            "medians over cases and both views; distances to the densely resampled true "
            "projected main vessel; radius error excludes the first and last "
            f"{END_EXCLUSION_PX:g} px of each trace"
        ),
    }


def format_table(result: dict) -> str:
    """Plain-text table of a :func:`run` result: one line per trace, then the medians."""
    if result.get("suite") == "varied":
        return _format_varied(result)
    head = (f"{'preset':<8}{'seed':>5}{'view':>5}{'len px':>8}{'rms px':>8}{'max px':>8}"
            f"{'r MAE':>7}{'r bias':>8}{'r px':>6}{'vess ms':>9}{'trace ms':>9}")
    lines = ["centerline benchmark: traced vs true projected centerline", head,
             "-" * len(head)]
    for r in result["rows"]:
        lines.append(
            f"{r['preset']:<8}{r['seed']:>5}{r['view']:>5}{r['length_px']:>8.0f}"
            f"{r['centerline_rms_px']:>8.3f}{r['centerline_max_px']:>8.2f}"
            f"{r['radius_mae_px']:>7.3f}{r['radius_bias_px']:>8.3f}"
            f"{r['radius_true_median_px']:>6.1f}{r['vesselness_ms']:>9.0f}{r['trace_ms']:>9.1f}"
        )
    for f in result["failures"]:
        lines.append(f"{f['preset']:<8}{f['seed']:>5}{f['view']:>5}  FAILED: {f['error']}")
    lines.append("-" * len(head))
    t = result["targets"]
    for key, unit in (("centerline_rms_px", "px"), ("radius_mae_px", "px"),
                      ("vesselness_ms", "ms"), ("trace_ms", "ms")):
        ok = "ok" if result[key] <= t[key] else "MISSED"
        lines.append(f"median {key:<18} {result[key]:8.3f} {unit}  (target <= {t[key]:g}: {ok})")
    lines.append(f"{result['traces']} traces from {result['cases']} cases; {result['notes']}")
    return "\n".join(lines)


# ------------------------------------------------------------------ varied suite
def _evaluate_varied_view(image: np.ndarray, view: ViewGeometry, clicks_px: np.ndarray,
                          case, name: str, vmap: VesselnessMap) -> dict:
    """One trace of the varied suite, given the image's vesselness ``vmap``, against the
    truth; raises what the tracing raises. The view is traced as the pipeline traces
    each view (``recon.pipeline._trace``: the intensity mapping resolved once on the
    whole image, or a display-processed file's Box-Cox power fitted on the trace)."""
    from recon.trace import trace_view

    pixel_mm = view.pixel_mm_at_isocenter
    angio = case_angiogram(image, view, name, case.chain)
    t1 = time.perf_counter()
    cl = trace_view(angio, np.asarray(clicks_px, dtype=float), vmap, name, pixel_mm, "auto")
    t2 = time.perf_counter()
    main_X, main_r = case.truth.vessels[0]
    dense, radius_true = _dense_truth(view, main_X, main_r)
    dist, nearest = cKDTree(dense).query(cl.points_px)
    s = cl.arclength_px
    inner = (s >= END_EXCLUSION_PX) & (s <= s[-1] - END_EXCLUSION_PX)
    r_true = radius_true[nearest[inner]]
    err_r = cl.radius_px[inner] - r_true
    gap, truth_length_px = truth_gap_px(cl.points_px, view, case.truth)
    far = gap > SUCCESS_PX
    return {
        "status": "lost" if np.any(far) else "ok",
        "success": bool(not np.any(far)),
        "n_points": int(len(cl.points_px)),
        "length_px": float(cl.length_px),
        "truth_length_px": truth_length_px,
        "truth_max_gap_px": float(gap.max()) if len(gap) else 0.0,
        "lost_px": float(np.sum(far) * 0.1),
        "centerline_rms_px": float(np.sqrt(np.mean(dist**2))),
        "centerline_max_px": float(dist.max()),
        "radius_mae_px": float(np.mean(np.abs(err_r))) if len(err_r) else float("nan"),
        "radius_bias_px": float(np.mean(err_r)) if len(err_r) else float("nan"),
        "radius_bias_pct": float(100.0 * np.mean(err_r / r_true)) if len(err_r) else float("nan"),
        "radius_true_median_px": float(np.median(radius_true[nearest])),
        "intensity_mapping": getattr(cl, "intensity_mapping", None),
        "trace_ms": 1e3 * (t2 - t1),
    }


def truth_gap_px(points_px: np.ndarray, view: ViewGeometry,
                 truth: PhantomTruth) -> tuple[np.ndarray, float]:
    """How far (px) each point of the projected true segment (every 0.1 px, the first and
    last :data:`END_EXCLUSION_PX` left out) lies from a trace ``points_px`` (N, 2), and
    the projected segment's length (px); ``view`` is the view's TRUE geometry and
    ``truth`` the case's truth. A trace succeeds where no gap exceeds :data:`SUCCESS_PX`."""
    seg, _ = _dense_truth(view, truth.segment_X_world, truth.segment_radius_mm, 0.1)
    seg_s = arclength(seg)
    seg_in = (seg_s >= END_EXCLUSION_PX) & (seg_s <= seg_s[-1] - END_EXCLUSION_PX)
    trace_dense, _ = _dense_polyline(np.asarray(points_px, dtype=float), 0.1)
    gap, _ = cKDTree(trace_dense).query(seg[seg_in])
    return gap, float(seg_s[-1])


def _dense_polyline(points: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    s = arclength(points)
    s_new = np.arange(0.0, s[-1] + 1e-9, step)
    return np.column_stack([np.interp(s_new, s, points[:, k]) for k in range(2)]), s_new


def _click_errors(vmap: VesselnessMap, clicks_px: np.ndarray, seg_px: np.ndarray) -> dict:
    """Each click's distance (px) to the densified true segment ``seg_px`` (P, 2), as
    clicked and snapped (NaN where the snap refuses)."""
    tree = cKDTree(seg_px)
    snapped = []
    for c in np.asarray(clicks_px, dtype=float):
        try:
            snapped.append(snap_click(vmap, c)[0])
        except ValueError:
            snapped.append(np.full(2, np.nan))
    snapped_px = np.asarray(snapped)
    d_snap = np.full(len(snapped_px), np.nan)
    ok = np.all(np.isfinite(snapped_px), axis=1)
    d_snap[ok] = tree.query(snapped_px[ok])[0]
    return {"click_error_px": tree.query(np.asarray(clicks_px, float))[0].tolist(),
            "snap_error_px": d_snap.tolist()}


def _catheter_row(image: np.ndarray, vmap: VesselnessMap, view: ViewGeometry,
                  clicks_px: np.ndarray, case) -> dict:
    """The catheter tubes found in one view (:func:`find_catheters`, given the clicks)
    against the phantom's guiding catheter: ``catheter_in_view`` (one is rendered and
    at least :data:`CATHETER_MIN_VISIBLE_MM` of it projects inside the field),
    ``catheter_hit`` (a tube found with at least 80 % of its points on the projected
    catheter: within its outer radius + 3 px), ``catheter_false`` (tubes found with
    under half of their points on it)."""
    tubes = find_catheters(vmap, image, clicks_px)
    truth = np.zeros((0, 2))
    visible = False
    if case.catheter is not None:
        projected = view.project(case.catheter.X_world)
        inside = vmap.valid[np.clip(np.rint(projected[:, 1]).astype(int), 0, view.rows - 1),
                            np.clip(np.rint(projected[:, 0]).astype(int), 0, view.cols - 1)]
        inside &= np.all((projected >= 0) & (projected < [view.cols, view.rows]), axis=1)
        truth = projected[inside]
        visible = 0.1 * len(truth) >= CATHETER_MIN_VISIBLE_MM  # X_world every 0.1 mm
    reach_px = (3.0 + (case.catheter.outer_radius_mm / vmap.pixel_mm
                       if case.catheter is not None and vmap.pixel_mm else 0.0))
    on = [float(np.mean(cKDTree(truth).query(t.points_px)[0] <= reach_px)) if len(truth)
          else 0.0 for t in tubes]
    return {"catheter_in_view": bool(visible),
            "catheter_hit": bool(any(f >= 0.8 for f in on)),
            "catheter_false": int(sum(f < 0.5 for f in on))}


def _catheter_figures(rows: list[dict]) -> dict:
    """Share of views with a visible catheter where it was found, and false tubes per view."""
    shown = [r["catheter_hit"] for r in rows if r.get("catheter_in_view")]
    return {"catheter_found": float(np.mean(shown)) if shown else None,  # none shown
            "catheter_views": len(shown),
            "catheter_false_per_view": float(np.mean([r.get("catheter_false", 0) for r in rows]))
            if rows else float("nan")}


def _varied_case_rows(spec) -> list[dict]:
    """Both views' rows of one varied-suite case (module level: runs in a worker)."""
    from recon.synth.suites import make_suite_case

    case = make_suite_case(spec)
    segment = case.seeds.segments[0]
    rows = []
    for name, image, view, clicks in (
        ("A", case.image_a, case.view_a, segment.a),
        ("B", case.image_b, case.view_b_true, segment.b),
    ):
        base = {"chain": spec.chain, "preset": spec.preset_name, "seed": spec.seed,
                "anatomy": spec.anatomy, "view": name, "size_px": int(view.cols),
                "pixel_spacing_mm": float(view.pixel_spacing_mm[0])}
        t0 = time.perf_counter()
        vmap = compute_vesselness(image, pixel_mm=view.pixel_mm_at_isocenter)
        base["vesselness_ms"] = 1e3 * (time.perf_counter() - t0)
        seg, _ = _dense_truth(view, case.truth.segment_X_world, case.truth.segment_radius_mm,
                              0.1)
        base.update(_click_errors(vmap, np.asarray(clicks, float), seg))
        base.update(_catheter_row(image, vmap, view, np.asarray(clicks, float), case))
        try:
            row = _evaluate_varied_view(image, view, clicks, case, name, vmap)
        except ValueError as err:  # TraceError (a CoronaryError) included: a failure
            row = {"status": "refused", "success": False, "error": " ".join(str(err).split())}
            row.update(_answered(image, view, np.asarray(clicks, float), case, name, vmap,
                                 seg, err, np.random.default_rng([spec.seed, ord(name)])))
        rows.append({**base, "answered_success": row["success"], "answered_waypoints": 0,
                     **row})
    return rows


def _answered(image: np.ndarray, view: ViewGeometry, clicks_px: np.ndarray, case, name: str,
              vmap: VesselnessMap, seg_px: np.ndarray, err: ValueError,
              rng: np.random.Generator) -> dict:
    """The trace after the clinician answers the tool's refusals: each refusal that names
    a place (``TraceError.near_px``) gets a waypoint clicked (:func:`click_px`) on the
    projected true segment ``seg_px`` (P, 2) nearest that place, in order along it, at
    most :data:`ANSWER_ROUNDS` times; a refusal that names no place stays a failure.
    Returns the row's ``answered_success`` and ``answered_waypoints`` (the waypoints
    added)."""
    from recon.synth.clicks import click_px

    s_seg = arclength(seg_px)
    tree = cKDTree(seg_px)
    clicks = np.asarray(clicks_px, float)
    added = 0
    while added < ANSWER_ROUNDS:
        near = getattr(err, "near_px", None)
        if near is None:
            break
        at = int(tree.query(near)[1])
        if not 0 < s_seg[at] < s_seg[-1]:
            break
        way = click_px(rng, seg_px[at][None])[0]
        s_clicks = s_seg[tree.query(clicks)[1]]
        pos = int(np.clip(np.searchsorted(s_clicks[1:-1], s_seg[at]) + 1, 1, len(clicks) - 1))
        clicks = np.insert(clicks, pos, way, axis=0)
        added += 1
        try:
            row = _evaluate_varied_view(image, view, clicks, case, name, vmap)
        except ValueError as again:
            err = again
            continue
        return {"answered_success": row["success"], "answered_waypoints": added}
    return {"answered_success": False, "answered_waypoints": added}


def _figures(rows: list[dict]) -> dict:
    """The per-chain (or overall) figures of a set of varied-suite trace rows."""
    done = [r for r in rows if r["status"] != "refused"]
    return {
        "cases": len({(r["chain"], r["preset"], r["seed"]) for r in rows}),
        "traces": len(rows),
        "trace_success": float(np.mean([r["success"] for r in rows])) if rows else float("nan"),
        "trace_success_answered": float(np.mean([r["answered_success"] for r in rows]))
        if rows else float("nan"),
        "refused": sum(r["status"] == "refused" for r in rows),
        "lost": sum(r["status"] == "lost" for r in rows),
        "centerline_rms_px": median(r["centerline_rms_px"] for r in done),
        "centerline_rms_px_p90": percentile([r["centerline_rms_px"] for r in done], 90),
        "radius_bias_pct": median(r["radius_bias_pct"] for r in done),
        "radius_mae_px": median(r["radius_mae_px"] for r in done),
        "vesselness_ms": median(r["vesselness_ms"] for r in rows),
        "trace_ms": median(r["trace_ms"] for r in done),
        **_click_figures(rows, "click_error_px"),
        **_click_figures(rows, "snap_error_px"),
        **_catheter_figures(rows),
    }


def _click_figures(rows: list[dict], key: str) -> dict:
    """Median, 90th percentile and fraction above SUCCESS_PX of one click-error key
    (a refused snap counts as above)."""
    d = np.array([e for r in rows for e in r.get(key, [])], dtype=float)
    if not len(d):
        return {f"{key}_median": float("nan"), f"{key}_p90": float("nan"),
                f"{key}_over_{SUCCESS_PX:g}": float("nan")}
    far = ~(d <= SUCCESS_PX)
    return {f"{key}_median": float(np.nanmedian(d)), f"{key}_p90": percentile(d, 90),
            f"{key}_over_{SUCCESS_PX:g}": float(np.mean(far))}


def _run_varied(per_chain: int, seed: int) -> dict:
    from recon.synth.suites import varied_cases

    specs = varied_cases(per_chain, seed)
    t0 = time.perf_counter()
    rows = [r for case_rows in parallel_map(_varied_case_rows, specs) for r in case_rows]
    chains: dict[str, dict] = {}
    for name in dict.fromkeys(spec.chain for spec in specs):
        chains[name] = _figures([r for r in rows if r["chain"] == name])
    anatomy = {a: _figures([r for r in rows if r["anatomy"] == a])
               for a in dict.fromkeys(spec.anatomy for spec in specs)}
    return {
        "suite": "varied",
        "cases": len(specs),
        "cases_per_chain": int(per_chain),
        "seed": int(seed),
        "chains": chains,
        "overall": _figures(rows),
        "anatomy": anatomy,
        "targets": {"trace_success": 0.98, "centerline_rms_px": 0.3, "abs_radius_bias_pct": 2.0},
        "rows": rows,
        "failures": [r for r in rows if not r["success"]],
        "wall_s": time.perf_counter() - t0,
        "notes": (
            f"trace success: no point of the projected true segment more than {SUCCESS_PX:g} "
            f"px from the trace (first and last {END_EXCLUSION_PX:g} px of the truth left out);"
            " a refused trace (TraceError) is a failure; answered: after a waypoint where each"
            f" refusal asks (at most {ANSWER_ROUNDS}); rms, radius: medians over the traces "
            "returned; radius_bias_pct: median of each trace's mean signed "
            "100 (fitted - true) / true"
        ),
    }


def _format_varied(result: dict) -> str:
    head = (f"{'chain':<22}{'cases':>6}{'traces':>7}{'success':>9}{'answered':>9}"
            f"{'refused':>8}{'lost':>6}{'rms px':>8}{'p90 px':>8}{'r bias %':>9}"
            f"{'r MAE px':>9}{'trace ms':>9}")
    lines = [f"centerline benchmark, varied suite ({result['cases_per_chain']} cases per chain, "
             f"seed {result['seed']})", head, "-" * len(head)]

    def line(name: str, f: dict) -> str:
        return (f"{name:<22}{f['cases']:>6}{f['traces']:>7}{f['trace_success']:>9.3f}"
                f"{f['trace_success_answered']:>9.3f}{f['refused']:>8}{f['lost']:>6}"
                f"{f['centerline_rms_px']:>8.3f}"
                f"{f['centerline_rms_px_p90']:>8.3f}{f['radius_bias_pct']:>+9.2f}"
                f"{f['radius_mae_px']:>9.3f}{f['trace_ms']:>9.0f}")

    lines += varied_rows(result, line, "-" * len(head))
    o, k = result["overall"], f"over_{SUCCESS_PX:g}"
    lines.append(
        f"clicks to the true segment, px (median / p90 / fraction above {SUCCESS_PX:g}): as "
        f"clicked {o['click_error_px_median']:.2f} / {o['click_error_px_p90']:.2f} / "
        f"{o[f'click_error_px_{k}']:.3f}; snapped {o['snap_error_px_median']:.2f} / "
        f"{o['snap_error_px_p90']:.2f} / {o[f'snap_error_px_{k}']:.3f}")
    found = "n/a" if o["catheter_found"] is None else f"{o['catheter_found']:.2f}"
    lines.append(
        f"guiding catheter: found in {found} of the {o['catheter_views']} "
        f"views that show one; false tubes per view {o['catheter_false_per_view']:.3f}")
    for r in result["failures"]:
        what = r.get("error") or (f"lost {r['lost_px']:.0f} px of the truth "
                                  f"(max gap {r['truth_max_gap_px']:.1f} px)")
        lines.append(f"FAILED {r['chain']} {r['preset']}/{r['seed']} {r['anatomy']} "
                     f"view {r['view']}: {what}")
    t = result["targets"]
    lines.append(f"targets: trace success >= {t['trace_success']}, rms <= "
                 f"{t['centerline_rms_px']} px, |radius bias| <= {t['abs_radius_bias_pct']} % "
                 "per chain")
    lines.append(f"{result['notes']}; {result['wall_s']:.0f} s wall")
    return "\n".join(lines)
