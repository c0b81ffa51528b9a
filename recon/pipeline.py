"""The whole reconstruction, top to bottom.

``reconstruct_pair`` is the one function that runs every stage in order;
the command line (`coronary3d reconstruct`) and the viewer both call it.

    trace both views -> calibrate view B on the clicked features (PALM, eq. 5)
    -> match (CBOCD + DP, eqs. 6-10)
    -> triangulate + smooth (eqs. 2-3) -> densitometric area (recon.lumen.densitometry)
    -> elliptic sections + surface
       (sec. 3.5, eq. 11) -> 3D measurements -> foreshortening and the best next view

Self-calibration (off by default, ``ReconstructionOptions.self_calibration``)
adds, after the first matching, a recalibration with the deviation pairs
(sec. 3.4.2), a refinement over the matched points and a second matching.

The output files (centerline CSV, report JSON, meshes) are written by
:mod:`recon.io.outputs`.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from recon import __version__
from recon.correspond import (
    ConsistencyResult,
    build_centerline_3d,
    check_consistency,
    match_centerlines,
    table3_metrics,
)
from recon.errors import CoronaryError
from recon.geometry import MIN_VIEW_SEPARATION_DEG, ViewGeometry, view_separation_deg
from recon.lumen import (
    Junction,
    LumenProfile,
    Measurements,
    SurfaceResult,
    build_surface,
    lumen_profile,
    measure_lumen,
    with_fill_ratios,
)
from recon.lumen.ffr import FFRError, FFRModel, FFRResult, vessel_ffr
from recon.lumen.lesions import LesionReport, lesion_report
from recon.pose import (
    CORRECTIONS,
    CalibrationResult,
    MeasurementIntervals,
    OptimalView,
    calibrate_supported,
    calibrate_with_curves,
    calibration_step,
    measurement_intervals,
    observability,
    optimal_view,
    self_calibrate,
)
from recon.seeds import Seeds
from recon.trace import VesselnessMap, compute_vesselness, trace_pair
from recon.trace3d import (
    CORRIDOR_MIN_PX,
    Path3D,
    ambiguous_stretches,
    path_shift_px,
    snap_ends,
    trace_in_3d,
)
from recon.types import Angiogram, Centerline2D, Centerline3D, Matching, arclength

__all__ = [
    "PipelineError",
    "ReconstructionOptions",
    "Reconstruction",
    "calibrate_from_seeds",
    "calibrate_view_b",
    "check_calibration",
    "input_warnings",
    "reconstruct_pair",
]

Progress = Callable[[str, float], None]

# ReconstructionOptions.calibration -> the corrections calibrate_supported may choose from
CALIBRATION_CHOICES: dict[str, tuple[str, ...]] = {
    "supported": tuple(CORRECTIONS),
    "full": ("full",),
    "header": ("header",),
    "curves": ("full",),  # the full clicks-only correction, then the curves jointly
}
#: The tracers: "2d" traces each view on its own (recon.trace); "3d" traces a 3D path
#: that both views vote on and refines each view in a corridor around its image
#: (recon.trace3d).
TRACER_CHOICES = ("2d", "3d")


class PipelineError(CoronaryError):
    """The inputs cannot be reconstructed (one line: what and why)."""


@dataclass(frozen=True)
class ReconstructionOptions:
    """Choices a user can make; the defaults are the paper's method without self-calibration.

    matcher : "match1".."match4" (the paper's names; match3 = CBOCD adaptive-step DP).
    optimizer : "palm", "lm" or "anneal" (the paper's Optimize 3, 2, 1).
    segment : index of the seeds segment to reconstruct.
    self_calibration : after matching, recalibrate with the deviation pairs
        (sec. 3.4.2) and refine over the matched centerline points. Off by
        default: the pairs are matched under the geometry being refined, so
        they largely agree with it (docs/benchmarks.md has the measurement).
    spacing_mm : arc-length spacing of the 3D centerline.
    intensity_a, intensity_b : how each view's stored values relate to the
        attenuation: "lin" (linear in X-ray intensity), "log" (linear in
        attenuation) or "auto" (the file's PixelIntensityRelationship when it
        says LIN or LOG, else estimated from the image; :mod:`recon.trace.intensity`).
    voxel_mm : surface grid size (None: chosen from the vessel radius).
    allow_close_views : go on (with a warning) when the views' central rays are less
        than :data:`MIN_VIEW_SEPARATION_DEG` apart; refused otherwise.
    calibration : how far view B moves from its header: "full" (all six rig
        parameters, the default), "supported" (the correction the clicks support,
        :func:`recon.pose.calibration.calibrate_supported`: the header, a translation of
        B's rig, or the full correction), "header" (B stays at its header pose) or
        "curves" (the full correction from the clicks and the two traced curves
        jointly, :func:`recon.pose.calibration_curves.calibrate_with_curves`).
    tracer : "2d" or "3d" (:data:`TRACER_CHOICES`). With "3d", view B is calibrated on the
        clicks first, then both views' traces come from a 3D path both views vote on.
    aortic_pressure_mmhg, ffr_velocity_m_s, ffr_split_exponent : the FFR model's mean
        aortic pressure, healthy hyperemic velocity and bifurcation flow-split exponent
        (:class:`recon.lumen.ffr.FFRModel`; its defaults).
        "supported" keeps good real headers (tests/recon/test_real_views.py) but its
        translation-only choice costs accuracy where the header is off in rotation
        too, as on the phantoms (docs/benchmarks.md); so it is not the default yet.
    """

    matcher: str = "match3"
    optimizer: str = "palm"
    segment: int = 0
    self_calibration: bool = False
    spacing_mm: float = 0.25
    voxel_mm: float | None = None
    intensity_a: str = "auto"
    intensity_b: str = "auto"
    allow_close_views: bool = False
    calibration: str = "full"
    tracer: str = "2d"
    aortic_pressure_mmhg: float = FFRModel.aortic_pressure_mmhg
    ffr_velocity_m_s: float = FFRModel.velocity_m_s
    ffr_split_exponent: float = FFRModel.split_exponent


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """Everything one reconstruction produced."""

    path_a: str
    path_b: str
    seeds: Seeds
    options: ReconstructionOptions
    view_a: ViewGeometry
    view_b_header: ViewGeometry
    view_b: ViewGeometry
    calibration: CalibrationResult
    calibration_steps: tuple[dict, ...]
    centerline_a: Centerline2D
    centerline_b: Centerline2D
    matching: Matching
    centerline_3d: Centerline3D
    surface: SurfaceResult
    profile: LumenProfile
    measurements: Measurements
    metrics: dict
    timings_ms: dict = field(default_factory=dict)
    # cross-view check of the 3D centerline (recon.correspond.consistency), and one-line warnings
    # about the inputs and the stretches that failed it
    consistency: ConsistencyResult | None = None
    warnings: tuple[str, ...] = ()
    optimal_view: OptimalView | None = None  # foreshortening map and the best next view
    # 95 % intervals of the measurements and the radius (recon.pose.uncertainty); None when
    # the calibration carries no posterior (self-calibration)
    intervals: MeasurementIntervals | None = None
    # FFR along the segment (recon.lumen.ffr; a model estimate for research), or None
    ffr: FFRResult | None = None
    # the 3D tracer's path (recon.trace3d), or None (the 2D tracer)
    path_3d: Path3D | None = None

    @functools.cached_property
    def lesions(self) -> LesionReport:
        """Every lesion of the segment (lesion 1, 2, ... proximal to distal) with its 95 %
        intervals from the intervals' draws, and which is the primary one, the one of
        ``measurements`` (:func:`recon.lumen.lesions.lesion_report`)."""
        return lesion_report(self.profile, () if self.intervals is None
                             else self.intervals.profiles)

    def report(self) -> dict:
        """JSON-ready report: inputs, geometry, calibration, matching, measurements, timings."""
        cal = self.calibration
        c3 = self.centerline_3d
        return {
            "software": {"name": "coronary3d", "version": __version__},
            "inputs": {
                "a": self.path_a,
                "b": self.path_b,
                "segment": self.seeds.segments[self.options.segment].name,
                "options": self.options.__dict__,
            },
            "geometry": {
                "view_a": self.view_a.to_dict(),
                "view_b_header": self.view_b_header.to_dict(),
                "view_b_calibrated": self.view_b.to_dict(),
                "view_separation_deg": view_separation_deg(self.view_a, self.view_b),
            },
            "calibration": {
                "method": cal.method,
                "iterations": cal.iterations,
                "ms": cal.elapsed_ms,
                "error_before_px": cal.error_before_px,
                "error_after_px": cal.error_after_px,
                "error_before_mm": cal.error_before_mm,
                "error_after_mm": cal.error_after_mm,
                "rotation_deg": float(np.degrees(np.linalg.norm(self.view_b.rotvec_corr))),
                "translation_mm": list(self.view_b.t_corr_mm),
                "warnings": list(cal.warnings),
                "steps": list(self.calibration_steps),
                "correction": cal.correction,
                "decision": cal.decision,
                "observability": (
                    observability(cal.posterior) if cal.posterior is not None else None
                ),
            },
            "matching": {
                "method": self.matching.method,
                "standard_view": self.matching.standard_view,
                "pairs": int(len(self.matching.points_a_px)),
                "max_row_min_cost_px": self.matching.max_row_min_cost_px,
                "deviation_pairs": int(len(self.matching.deviation_a_px)),
                "table3": self.metrics,
            },
            "centerline": {
                "points": int(len(self.centerline_3d.s_mm)),
                "length_mm": self.centerline_3d.length_mm,
                "traced_length_a_px": self.centerline_a.length_px,
                "traced_length_b_px": self.centerline_b.length_px,
                # 3D arc-length stretches [start, end] mm where that view's radius was
                # not trusted (another vessel over it) and the other view's stood in
                "overlap_a_mm": c3.overlap_stretches_mm("a"),
                "overlap_b_mm": c3.overlap_stretches_mm("b"),
            },
            "mesh": {
                "vertices": int(len(self.surface.mesh.vertices)),
                "faces": int(len(self.surface.mesh.faces)),
                "watertight": bool(self.surface.mesh.is_watertight),
                "volume_mm3": float(self.surface.mesh.volume),
            },
            "measurements": {**self.measurements.to_dict(), **_ffr_value(self.ffr)},
            "measurements_ci95": (
                {k: list(v) for k, v in self.intervals.ci95.items()} | _ffr_ci95(self.ffr)
                if self.intervals is not None else None
            ),
            "ffr": self.ffr.to_dict() if self.ffr is not None else None,
            # every lesion with its intervals, and whether "the" lesion stands out
            "lesions": self.lesions.lesion_list(),
            "lesion_assessment": self.lesions.assessment(),
            "uncertainty": _uncertainty_report(self.intervals),
            # how each view's stored values were taken to relate to attenuation, and why
            "intensity": {
                "a": _intensity_report(self.centerline_a),
                "b": _intensity_report(self.centerline_b),
            },
            # catheter-like tubes found in each view (field edge -> tip), which the
            # trace was kept from following
            "guiding_catheter": {
                "a": _catheter_report(self.centerline_a),
                "b": _catheter_report(self.centerline_b),
            },
            "consistency": self.consistency.to_dict() if self.consistency is not None else None,
            "optimal_view": (self.optimal_view.to_dict() if self.optimal_view is not None
                             else None),
            "tracer": _tracer_report(self.options.tracer, self.path_3d),
            "warnings": list(self.warnings),
            "timings_ms": self.timings_ms,
        }


def _tracer_report(tracer: str, path: Path3D | None) -> dict:
    """The tracer used and, for the 3D tracer, the stretches two views cannot settle."""
    if path is None:
        return {"kind": tracer}
    return {"kind": tracer, "path_length_mm": round(float(path.s_mm[-1]), 2),
            "ambiguous_stretches": ambiguous_stretches(path)}


def _notify(progress: Progress | None, stage: str, fraction: float) -> None:
    if progress is not None:
        progress(stage, fraction)


def _segment(seeds: Seeds, index: int):
    if not seeds.segments:
        raise PipelineError("seeds: no segment to reconstruct (segments is empty)")
    if not 0 <= index < len(seeds.segments):
        raise PipelineError(
            f"seeds: segment {index} does not exist ({len(seeds.segments)} segment(s))"
        )
    return seeds.segments[index]


def _features(seeds: Seeds, segment_index: int, cl_a: Centerline2D | None = None,
              cl_b: Centerline2D | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Corresponding features (K, 2) per view: the segment ends (snapped when traced)
    and the feature landmarks."""
    seg = _segment(seeds, segment_index)
    ends_a = cl_a.points_px[[0, -1]] if cl_a is not None else seg.a[[0, -1]]
    ends_b = cl_b.points_px[[0, -1]] if cl_b is not None else seg.b[[0, -1]]
    pa = [ends_a] + [np.asarray([f.a_px]) for f in seeds.features]
    pb = [ends_b] + [np.asarray([f.b_px]) for f in seeds.features]
    return np.vstack(pa), np.vstack(pb)


def _pose_from_clicks(seeds: Seeds, options: ReconstructionOptions,
                      vmaps: tuple[VesselnessMap, VesselnessMap], view_a: ViewGeometry,
                      view_b_header: ViewGeometry) -> CalibrationResult:
    """View B calibrated on the end clicks (snapped, or as clicked where that meets the
    other view better) and the landmarks: the pose before any trace."""
    seg = _segment(seeds, options.segment)
    ends_a, ends_b = snap_ends(vmaps, seg.a, seg.b, view_a, view_b_header)
    pa = np.vstack([ends_a] + [np.asarray([f.a_px]) for f in seeds.features])
    pb = np.vstack([ends_b] + [np.asarray([f.b_px]) for f in seeds.features])
    return calibrate_view_b(view_a, view_b_header, pa, pb, options)


def _pose_tolerance_px(cal: CalibrationResult) -> float:
    """B's remaining pose error (px) the 3D path allows across the epipolar lines: twice
    the calibration's mean back-projection error, 1-4 px."""
    return float(np.clip(2.0 * cal.error_after_px, 1.0, 4.0))


def check_calibration(options: ReconstructionOptions) -> None:
    """Refuse an ``options.calibration`` that is not a rule of :data:`CALIBRATION_CHOICES`."""
    if options.calibration not in CALIBRATION_CHOICES:
        raise PipelineError(f"unknown calibration {options.calibration!r} (use one of "
                            f"{', '.join(CALIBRATION_CHOICES)})")


def calibrate_view_b(
    view_a: ViewGeometry, view_b_header: ViewGeometry, feat_a: np.ndarray, feat_b: np.ndarray,
    options: ReconstructionOptions, curves: tuple[np.ndarray, np.ndarray] | None = None,
) -> CalibrationResult:
    """View B calibrated on the corresponding features (K, 2) per view by the rule
    ``options.calibration`` (:class:`ReconstructionOptions`); ``curves`` are the traced
    centerlines (N, 2) per view that the "curves" rule adds (ignored by the others)."""
    check_calibration(options)
    cal = calibrate_supported(view_a, view_b_header, feat_a, feat_b, method=options.optimizer,
                              candidates=CALIBRATION_CHOICES[options.calibration])
    if options.calibration == "curves" and curves is not None:
        cal = calibrate_with_curves(view_a, view_b_header, feat_a, feat_b, curves[0], curves[1],
                                    initial=cal)
    return cal


def calibrate_from_seeds(
    angio_a: Angiogram, angio_b: Angiogram, seeds: Seeds, optimizer: str = "palm",
    segment: int = 0, vesselness: tuple[VesselnessMap, VesselnessMap] | None = None,
    intensity: tuple[str, str] = ("auto", "auto"), calibration: str = "full",
) -> CalibrationResult:
    """Calibrate view B on the clicked correspondences (the viewer's Calibrate), with
    the same correction rule (``calibration``, as :class:`ReconstructionOptions`).

    With ``vesselness`` (both views' maps) the segment is traced first and its traced
    ends are used, exactly as in :func:`reconstruct_pair`'s calibration step, so both
    report the same figures for the same clicks; without, the clicked ends are used.
    """
    cl_a = cl_b = None
    if vesselness is not None:
        seg = _segment(seeds, segment)
        cl_a, cl_b = trace_pair(
            (angio_a, angio_b), (seg.a, seg.b), vesselness,
            (angio_a.geometry.pixel_mm_at_isocenter, angio_b.geometry.pixel_mm_at_isocenter),
            intensity)
    pa, pb = _features(seeds, segment, cl_a, cl_b)
    curves = (cl_a.points_px, cl_b.points_px) if cl_a is not None and cl_b is not None else None
    return calibrate_view_b(angio_a.geometry, angio_b.geometry, pa, pb,
                            ReconstructionOptions(optimizer=optimizer, calibration=calibration),
                            curves)


def reconstruct_pair(
    angio_a: Angiogram,
    angio_b: Angiogram,
    seeds: Seeds,
    options: ReconstructionOptions | None = None,
    progress: Progress | None = None,
    vesselness: tuple[VesselnessMap, VesselnessMap] | None = None,
    *,
    traced: tuple[Centerline2D, Centerline2D] | None = None,
    calibration: CalibrationResult | None = None,
    junction: Junction | None = None,
    best_view: bool = True,
) -> Reconstruction:
    """Run every stage on one segment of a pair of angiograms.

    Parameters
    ----------
    angio_a, angio_b : the reference view A and view B (header geometry).
    seeds : the clinician's clicks; ``options.segment`` selects the segment.
    progress : called as ``progress(stage, fraction)`` before each stage.
    vesselness : the two images' vesselness maps when the caller already has
        them (the viewer computes them once per image for snapping).
    traced, calibration : the segment's two traces and view B's calibration
        when the caller made them (the tree, :mod:`recon.tree`, traces every
        branch and calibrates once for all); those stages are then skipped.
    junction : a branch's parent; the 3D centerline's start is joined to it
        (:meth:`recon.lumen.bifurcation.Junction.join`).
    best_view : compute the best next view (``optimal_view``); the tree turns it off
        and chooses each branch's view with the other branches in sight.
    """
    options = options or ReconstructionOptions()
    seg = _segment(seeds, options.segment)
    check_calibration(options)
    model = ffr_model(options)  # a pressure or velocity out of range: refused before any work
    if options.tracer not in TRACER_CHOICES:
        raise PipelineError(f"unknown tracer {options.tracer!r} (use one of "
                            f"{', '.join(TRACER_CHOICES)})")
    view_a, view_b_header = angio_a.geometry, angio_b.geometry
    close_views = _check_separation(view_a, view_b_header, options.allow_close_views)
    timings: dict[str, float] = {}
    clock = time.perf_counter()

    def lap(name: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[name] = round((now - clock) * 1000.0, 2)
        clock = now

    # 1. Vessel centerline, radius and brightness in each view (sec. 3.3.1).
    _notify(progress, "tracing the vessel in both views", 0.0)
    pixel_mm_a, pixel_mm_b = view_a.pixel_mm_at_isocenter, view_b_header.pixel_mm_at_isocenter
    if vesselness is None:
        vesselness = (
            compute_vesselness(angio_a.image, pixel_mm=pixel_mm_a),
            compute_vesselness(angio_b.image, pixel_mm=pixel_mm_b),
        )
    intensity = (options.intensity_a, options.intensity_b)
    path3d = None
    if traced is None and options.tracer == "3d":
        # 1'. Pose first: B calibrated on the end clicks and the landmarks (no trace needed);
        #     then a 3D path that both views vote on fixes each view's trace (recon.trace3d).
        pre = _pose_from_clicks(seeds, options, vesselness, view_a, view_b_header)
        tol_px = _pose_tolerance_px(pre)
        t3 = trace_in_3d((angio_a, angio_b), (seg.a, seg.b), vesselness, view_a, pre.view_b,
                         intensity, tol_px)
        traced, path3d = t3.traced, t3.path
    elif traced is None:
        traced = trace_pair((angio_a, angio_b), (seg.a, seg.b), vesselness,
                            (pixel_mm_a, pixel_mm_b), intensity)
    cl_a, cl_b = traced
    lap("trace")

    # 2. Calibrate view B on the corresponding features (eq. 5, PALM).
    _notify(progress, "calibrating the geometry", 0.35)
    feat_a, feat_b = _features(seeds, options.segment, cl_a, cl_b)
    cal = calibration or calibrate_view_b(view_a, view_b_header, feat_a, feat_b, options,
                                          (cl_a.points_px, cl_b.points_px))
    if path3d is not None and path_shift_px(path3d, pre.view_b, cal.view_b) > max(
            tol_px, CORRIDOR_MIN_PX):
        # the pose on the traces moved the path's image in B out of the corridor: again
        t3 = trace_in_3d((angio_a, angio_b), (seg.a, seg.b), vesselness, view_a, cal.view_b,
                         intensity, tol_px, t3.evidence)
        (cl_a, cl_b), path3d = t3.traced, t3.path
        feat_a, feat_b = _features(seeds, options.segment, cl_a, cl_b)
        cal = calibrate_view_b(view_a, view_b_header, feat_a, feat_b, options,
                               (cl_a.points_px, cl_b.points_px))
    steps = [calibration_step("features" if calibration is None else "tree", cal)]
    lap("calibrate")

    # 3. Point correspondence: epipolar COST, CBOCD, adaptive-step DP (eqs. 6-10).
    _notify(progress, "matching points between the views", 0.5)
    matching = match_centerlines(cl_a, cl_b, view_a, cal.view_b, method=options.matcher)
    lap("match")

    # 4. Self-calibration (sec. 3.4.2): deviation pairs become features, then a
    #    refinement over all matched points; matching is redone with the result.
    if options.self_calibration:
        _notify(progress, "refining the geometry with the matched points", 0.6)
        cal, matching, extra = self_calibrate(
            view_a, view_b_header, feat_a, feat_b, cl_a, cl_b, cal, matching,
            options.optimizer, options.matcher)
        steps += extra
        lap("self_calibrate")

    # 5. Triangulation and the smooth 3D centerline (eqs. 2-3, eq. 11 radii).
    _notify(progress, "triangulating the 3D centerline", 0.7)
    cl3d = build_centerline_3d(matching, view_a, cal.view_b, spacing_mm=options.spacing_mm)
    if junction is not None:
        cl3d = junction.join(cl3d)
    # 5a. Densitometry: each view's attenuation across the vessel, calibrated where the
    #     lumen is round, gives the area where the two calipers disagree.
    cl3d = with_fill_ratios(cl3d, view_a, cal.view_b)
    metrics = table3_metrics(cl3d, matching, view_a, cal.view_b)
    lap("triangulate")

    # 5b. Cross-view consistency: the 3D centerline back on both images.
    consistency = check_consistency(cl3d, view_a, cal.view_b, cl_a, cl_b,
                                    vesselness[0].response, vesselness[1].response)
    warnings = close_views + input_warnings(angio_a.info, "A") + input_warnings(angio_b.info, "B")
    warnings += [f"view {st.view.upper()}, {st.start_mm:.1f}-{st.end_mm:.1f} mm of the 3D "
                 f"centerline: {st.reason}" for st in consistency.stretches]
    if path3d is not None:
        warnings += [f"{st['start_mm']:.1f}-{st['end_mm']:.1f} mm of the 3D path "
                     f"{st['reason']}; check the trace there" for st in ambiguous_stretches(path3d)]
    lap("consistency")

    # 6. Elliptic cross-sections and the watertight surface (sec. 3.5).
    _notify(progress, "building the surface mesh", 0.8)
    surface = build_surface(cl3d, view_a, cal.view_b, voxel_mm=options.voxel_mm)
    lap("surface")

    # 7. 3D quantitative coronary analysis.
    _notify(progress, "measuring the lumen", 0.95)
    profile = lumen_profile(cl3d.s_mm, surface.sections.area_mm2)
    measurements = measure_lumen(profile)
    lap("measure")

    # 8. Foreshortening in both views and the best next view (recon.pose.optimal_view).
    next_view = None
    if best_view:
        next_view = optimal_view(cl3d.X_world, profile.smooth_radius_at(cl3d.s_mm), view_a,
                                 {"a": view_a, "b": cal.view_b})
    lap("optimal_view")

    # 9. 95 % intervals: the pose posterior and the 2D radius error, sampled.
    intervals = None
    if cal.posterior is not None:
        _notify(progress, "estimating the intervals", 0.97)
        intervals = measurement_intervals(view_a, view_b_header, cal.posterior, cl3d,
                                          measurements, flagged_a=consistency.a.flagged,
                                          flagged_b=consistency.b.flagged)
        lap("intervals")

    # 10. FFR along the segment and its interval over the intervals' draws (recon.lumen.ffr);
    #     a tree's branch is solved with its whole tree (recon.tree).
    #     A lumen the model cannot carry (it closes, or is too short) leaves the QCA
    #     standing: no FFR, and a warning that says why.
    ffr = None
    if junction is None:
        try:
            ffr = vessel_ffr(profile, intervals.profiles if intervals is not None else (),
                             model, seg.name)
        except FFRError as err:
            warnings.append(f"FFR not computed: {err}")
        lap("ffr")
    timings["total"] = round(sum(timings.values()), 2)
    _notify(progress, "done", 1.0)

    return Reconstruction(
        path_a=angio_a.path,
        path_b=angio_b.path,
        seeds=seeds,
        options=options,
        view_a=view_a,
        view_b_header=view_b_header,
        view_b=cal.view_b,
        calibration=cal,
        calibration_steps=tuple(steps),
        centerline_a=cl_a,
        centerline_b=cl_b,
        matching=matching,
        centerline_3d=cl3d,
        surface=surface,
        profile=profile,
        measurements=measurements,
        metrics=metrics,
        timings_ms=timings,
        consistency=consistency,
        warnings=tuple(warnings),
        optimal_view=next_view,
        intervals=intervals,
        ffr=ffr,
        path_3d=path3d,
    )


def _check_separation(view_a: ViewGeometry, view_b: ViewGeometry, allow: bool) -> list[str]:
    """Refuse two views whose central rays are less than :data:`MIN_VIEW_SEPARATION_DEG`
    apart (their epipolar lines run nearly along the vessel, so a small error in the
    clicks or the header becomes a large error in depth); with ``allow``, the
    warning line instead ([] when the views are far enough apart). Two views from
    one source position are refused in any case."""
    separation = view_separation_deg(view_a, view_b)
    if separation >= MIN_VIEW_SEPARATION_DEG:
        return []
    baseline_mm = float(np.linalg.norm(view_a.source_world - view_b.source_world))
    if baseline_mm < 1.0:
        raise PipelineError(f"views A and B project from the same place ({baseline_mm:.2f} mm "
                            "between their sources: one view paired with itself?), so no "
                            "depth can be recovered; choose two different views")
    what = (f"views A and B are {separation:.1f} deg apart (at least "
            f"{MIN_VIEW_SEPARATION_DEG:.0f} deg needed to fix depth)")
    if not allow:
        raise PipelineError(f"{what}; choose two views further apart, or give "
                            "--allow-close-views to go on anyway")
    return [f"{what}; depth and every 3D figure are unreliable"]


def input_warnings(info: dict, view: str) -> list[str]:
    """One line when an input's radii are less certain: an 8-bit, lossy or
    display-processed image (PixelIntensityRelationship (0028,1040) other than
    LIN/LOG), from ``Angiogram.info``; [] otherwise (or when not recorded)."""
    words, details = [], []
    bits = info.get("bits_stored")
    if bits is not None and int(bits) <= 8:
        words.append(f"{int(bits)}-bit")
    if info.get("lossy"):
        words.append("lossy")
        details.append(info.get("transfer_syntax_name") or "lossy compression")
    relationship = info.get("pixel_intensity_relationship")
    if relationship is not None and str(relationship).upper() not in ("LIN", "LOG"):
        words.append("display-processed")
        details.append(f"PixelIntensityRelationship {relationship}")
    if not words:
        return []
    more = f" ({'; '.join(details)})" if details else ""
    return [f"view {view}: {', '.join(words)} image{more}; its radii are less certain"]


def ffr_model(options: ReconstructionOptions) -> FFRModel:
    """The FFR model of ``options`` (FFRError when a value is outside its physical range)."""
    return FFRModel(aortic_pressure_mmhg=options.aortic_pressure_mmhg,
                    velocity_m_s=options.ffr_velocity_m_s,
                    split_exponent=options.ffr_split_exponent)


def _ffr_value(ffr: FFRResult | None) -> dict:
    """``measurements.ffr``: the distal FFR ({} without one)."""
    return {} if ffr is None else {"ffr": round(ffr.distal, 4)}


def _ffr_ci95(ffr: FFRResult | None) -> dict:
    """``measurements_ci95.ffr``: the distal FFR's 95 % interval ({} without one)."""
    return {} if ffr is None or ffr.ci95 is None else {"ffr": [round(v, 4) for v in ffr.ci95]}


def _uncertainty_report(intervals: MeasurementIntervals | None) -> dict | None:
    """How the 95 % intervals were made (None without them)."""
    if intervals is None:
        return None
    return {
        "method": "sampled: view B's pose from the calibration's Laplace posterior, each "
        "view's 2D radius error (from the two views' disagreement) and an error both "
        "views share (common_sd_px, assumed), re-triangulated and re-measured per draw; "
        "interval = value +- 1.96 sd",
        "samples": intervals.n_samples,
        "lesion_found_fraction": intervals.lesion_found_fraction,
        "radius_error": intervals.radius_error,
        # stretches (per view A, B; mm) the cross-view check flagged: drawn also as
        # "that view is wrong there" (its radius from the other view, a detour removed)
        "flagged_mm": intervals.flagged_mm,
    }


def _catheter_report(cl: Centerline2D) -> list[dict]:
    """The catheter tubes of one view: where each enters the field, its tip, its length."""
    out = []
    for pts in cl.catheters_px:
        out.append({"entry_px": [round(float(v), 1) for v in pts[0]],
                    "tip_px": [round(float(v), 1) for v in pts[-1]],
                    "length_px": round(float(arclength(pts)[-1]), 1)})
    return out


def _intensity_report(cl: Centerline2D) -> dict:
    """How a view's stored values were read: the mapping, why, and the fitted model."""
    return {
        "mapping": cl.intensity_mapping,
        "reason": cl.intensity_reason,
        "power": cl.intensity_power,
        "blur_px": cl.blur_px,
    }
