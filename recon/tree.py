"""The vessel tree: every segment of the seeds in one reconstruction.

    trace every segment in both views; a view's radius untrusted where another
    segment's lumen overlaps it there
    -> calibrate view B once on the whole tree (every segment's ends, every
    feature, by the rule of ``options.calibration``; with self-calibration
    also the matched centerline points of all of them, robust loss)
    -> a branch's origin stretch redrawn from the other view where, in one
       view, its trace runs inside the parent's lumen
    -> per segment, parents first: the stages of ``reconstruct_pair``
       (matching, triangulation, sections, QCA) with the tree's calibration,
       a branch joined to its parent at the bifurcation
    -> branch QCA from the carina on, bifurcation QCA (recon.lumen.bifurcation)
    -> one watertight mesh, the union of the branches (recon.lumen.surface)

A tree of one segment is exactly ``reconstruct_pair`` of that segment.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
import trimesh

from recon.correspond import match_centerlines, point_polyline_distance
from recon.errors import CoronaryError
from recon.geometry import ViewGeometry, triangulate
from recon.lumen import (
    BifurcationQCA,
    Junction,
    TreeSurface,
    bifurcation_qca,
    build_tree_surface,
    carina_s_mm,
    fill_names,
    literal,
    lumen_profile,
    measure_lumen,
)
from recon.lumen.bifurcation import nearest_on_polyline
from recon.lumen.ffr import FFRError, FFRVessel, Lumen, tree_ffr
from recon.lumen.lesions import ostium_zone_end_s_mm
from recon.pipeline import (
    PipelineError,
    Progress,
    Reconstruction,
    ReconstructionOptions,
    _check_separation,
    _notify,
    _pose_from_clicks,
    _pose_tolerance_px,
    calibrate_view_b,
    check_calibration,
    ffr_model,
    reconstruct_pair,
)
from recon.pose import CalibrationResult, measurement_intervals, optimal_view, refine_with_matches
from recon.seeds import Seeds, Segment
from recon.trace import TraceError, VesselnessMap, compute_vesselness, trace_pair
from recon.trace3d import evidence_pair, trace_in_3d
from recon.types import Angiogram, Centerline2D, arclength

__all__ = [
    "TreeReconstruction",
    "reconstruct_tree",
    "tree_calibration",
    "MATCHED_POINTS_PER_BRANCH",
]

#: Matched centerline pairs per branch that join the tree-wide calibration.
MATCHED_POINTS_PER_BRANCH = 60


@dataclass(frozen=True, eq=False)
class TreeReconstruction:
    """Every segment's reconstruction, the bifurcations and the tree's mesh.

    ``branches[k]`` is segment k of the seeds (a full :class:`Reconstruction`
    with view B calibrated on the whole tree; a branch's measurements are
    taken from its carina on). The top-level properties are the first
    segment's, so a tree reads like a one-segment reconstruction.
    """

    seeds: Seeds
    branches: tuple[Reconstruction, ...]
    bifurcations: tuple[BifurcationQCA, ...]
    tree_surface: TreeSurface
    calibration: CalibrationResult
    timings_ms: dict

    @property
    def first(self) -> Reconstruction:
        return self.branches[0]

    @property
    def measurements(self):
        return self.first.measurements

    @property
    def warnings(self) -> tuple[str, ...]:
        """The first segment's warnings, the other branches' named by their segment (a
        line the first segment already gave, such as an input file's, once), and the
        bifurcations' origin warnings."""
        seen: dict[str, None] = {}
        for rec in self.branches:
            for line in rec.warnings:
                if line in seen:  # the same input fact (a file's bit depth, its mapping)
                    continue
                seen.setdefault(line if rec is self.first else f"{self._name(rec)}: {line}")
        for bif in self.bifurcations:
            if bif.origin_warning is not None:
                seen.setdefault(bif.origin_warning)
        return tuple(seen)

    @property
    def mesh(self) -> trimesh.Trimesh:
        return self.tree_surface.mesh

    def _name(self, rec: Reconstruction) -> str:
        return self.seeds.segments[rec.options.segment].name

    def report(self) -> dict:
        """The first segment's report, plus ``branches``, ``bifurcations`` and ``tree``."""
        out = self.first.report()
        out["warnings"] = list(self.warnings)
        out["branches"] = []
        for rec in self.branches:
            entry = rec.report()
            entry["branch_id"] = rec.options.segment
            entry["parent"] = self.seeds.segments[rec.options.segment].parent
            out["branches"].append(entry)
        out["bifurcations"] = [b.to_dict() for b in self.bifurcations]
        mesh = self.tree_surface.mesh
        out["tree"] = {
            "segments": len(self.branches),
            "mesh": {
                "vertices": int(len(mesh.vertices)),
                "faces": int(len(mesh.faces)),
                "watertight": bool(mesh.is_watertight),
                "components": self.tree_surface.components,
                "cavities_removed": self.tree_surface.cavities,
                "specks_removed": self.tree_surface.specks,
                "volume_mm3": float(mesh.volume),
                "voxel_mm": self.tree_surface.voxel_mm,
            },
            "timings_ms": self.timings_ms,
        }
        return out


def _tree_features(seeds: Seeds, traced: list[tuple[Centerline2D, Centerline2D]]
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(K, 2) per view: every segment's traced ends, then every feature."""
    pa = [cl_a.points_px[[0, -1]] for cl_a, _ in traced]
    pb = [cl_b.points_px[[0, -1]] for _, cl_b in traced]
    pa += [np.asarray([f.a_px]) for f in seeds.features]
    pb += [np.asarray([f.b_px]) for f in seeds.features]
    return np.vstack(pa), np.vstack(pb)


def tree_calibration(angio_a: Angiogram, angio_b: Angiogram, seeds: Seeds,
                     traced: list[tuple[Centerline2D, Centerline2D]],
                     options: ReconstructionOptions) -> CalibrationResult:
    """View B calibrated on the whole tree.

    The features: every segment's ends and every feature (eq. 5), calibrated by
    the rule ``options.calibration`` as one segment is
    (:func:`recon.pipeline.calibrate_view_b`; "curves" adds the first
    segment's two traced curves). With
    ``options.self_calibration`` and two or more segments the matched
    centerline points of all of them (:data:`MATCHED_POINTS_PER_BRANCH`
    each, matched under that first pose) are added with the robust loss
    (:func:`recon.pose.calibration.refine_with_matches`); off by default, as for
    one segment (docs/benchmarks.md, the tree suite, has the measurement).
    """
    view_a, view_b = angio_a.geometry, angio_b.geometry
    feat_a, feat_b = _tree_features(seeds, traced)
    cl_a, cl_b = traced[0]
    cal = calibrate_view_b(view_a, view_b, feat_a, feat_b, options,
                           (cl_a.points_px, cl_b.points_px))
    if len(traced) < 2 or options.optimizer != "palm" or not options.self_calibration:
        return cal
    matched_a, matched_b = [], []
    for cl_a, cl_b in traced:
        m = match_centerlines(cl_a, cl_b, view_a, cal.view_b, method=options.matcher)
        stride = max(1, len(m.points_a_px) // MATCHED_POINTS_PER_BRANCH)
        matched_a.append(m.points_a_px[::stride])
        matched_b.append(m.points_b_px[::stride])
    return refine_with_matches(view_a, view_b, feat_a, feat_b, np.vstack(matched_a),
                               np.vstack(matched_b), initial=cal)


def reconstruct_tree(
    angio_a: Angiogram,
    angio_b: Angiogram,
    seeds: Seeds,
    options: ReconstructionOptions | None = None,
    progress: Progress | None = None,
    vesselness: tuple[VesselnessMap, VesselnessMap] | None = None,
) -> TreeReconstruction:
    """Reconstruct every segment of ``seeds`` (module docstring); segment 0 first."""
    options = options or ReconstructionOptions()
    if not seeds.segments:
        raise PipelineError("seeds: no segment to reconstruct (segments is empty)")
    check_calibration(options)
    ffr_model(options)  # a pressure or velocity out of range: refused before any work
    _check_separation(angio_a.geometry, angio_b.geometry, options.allow_close_views)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    _notify(progress, f"tracing {len(seeds.segments)} segment(s) in both views", 0.0)
    view_a, view_b = angio_a.geometry, angio_b.geometry
    if vesselness is None:
        vesselness = (compute_vesselness(angio_a.image, pixel_mm=view_a.pixel_mm_at_isocenter),
                      compute_vesselness(angio_b.image, pixel_mm=view_b.pixel_mm_at_isocenter))
    one = len(seeds.segments) == 1
    # the 3D tracer: view B calibrated on the root's end clicks and the landmarks first
    # (the one-segment reconstruction does it itself)
    pose = None
    if options.tracer == "3d" and not one:
        pre = _pose_from_clicks(seeds, replace(options, segment=0), vesselness, view_a, view_b)
        pose = (pre.view_b, _pose_tolerance_px(pre), evidence_pair((angio_a, angio_b), vesselness))
    traced = [None] if one and options.tracer == "3d" else [
        _trace_both(angio_a, angio_b, seg, vesselness, options, len(seeds.segments), pose)
        for seg in seeds.segments]
    if len(traced) > 1:
        traced = _mark_tree_overlaps(traced)
    timings["trace"] = _ms(t0)
    if one:  # exactly the one-segment reconstruction
        rec = reconstruct_pair(angio_a, angio_b, seeds, replace(options, segment=0), progress,
                               vesselness, traced=traced[0])
        calibration = rec.calibration
        branches = [rec]
    else:
        _notify(progress, "calibrating the geometry on the whole tree", 0.2)
        t1 = time.perf_counter()
        calibration = tree_calibration(angio_a, angio_b, seeds, traced, options)
        timings["calibrate"] = _ms(t1)
        branches = []
        per_branch = replace(options, self_calibration=False)
        mismatches: dict[int, OriginMismatch | OriginUnseen] = {}
        for k, seg in enumerate(seeds.segments):
            if seg.parent is not None:
                traced[k], mismatch = _origin_from_the_clear_view(
                    traced[k], traced[seeds.segment_index(seg.parent)], view_a,
                    calibration.view_b)
                if mismatch is not None:
                    mismatches[k] = mismatch
        for k, seg in enumerate(seeds.segments):
            _notify(progress, f"segment {seg.name}", 0.3 + 0.5 * k / len(seeds.segments))
            junction = None
            if seg.parent is not None:
                parent = branches[seeds.segment_index(seg.parent)]
                junction = Junction(parent.centerline_3d.X_world,
                                    np.sqrt(parent.surface.sections.area_mm2 / np.pi))
            # a joined branch is measured from its carina on, which the whole branch's
            # intervals would not describe: _from_carina samples them from there
            rec = reconstruct_pair(angio_a, angio_b, seeds, replace(per_branch, segment=k),
                                   None, vesselness, traced=traced[k],
                                   calibration=calibration if junction is None
                                   else replace(calibration, posterior=None),
                                   junction=junction, best_view=False)
            if junction is not None:
                rec = _from_carina(replace(rec, calibration=calibration), junction)
            branches.append(rec)
        branches = _best_views_among_branches(branches)
        branches = _with_tree_ffr(seeds, branches, options)
    _notify(progress, "building the tree's surface", 0.85)
    t1 = time.perf_counter()
    if len(branches) == 1:  # the segment's own surface is the tree's
        mesh = branches[0].surface.mesh
        labels = trimesh.graph.connected_component_labels(mesh.face_adjacency, len(mesh.faces))
        tree_surface = TreeSurface(mesh=mesh, components=int(labels.max()) + 1 if labels.size
                                   else 0, voxel_mm=branches[0].surface.voxel_mm, grid_voxels=0)
    else:
        tree_surface = build_tree_surface([rec.surface.sections for rec in branches],
                                          voxel_mm=options.voxel_mm)
    timings["tree_surface"] = _ms(t1)
    bifurcations = tuple(_bifurcation(seeds, branches, k, mismatches.get(k))
                         for k, seg in enumerate(seeds.segments) if seg.parent is not None)
    timings["total"] = _ms(t0)
    _notify(progress, "done", 1.0)
    return TreeReconstruction(seeds=seeds, branches=tuple(branches), bifurcations=bifurcations,
                              tree_surface=tree_surface, calibration=calibration,
                              timings_ms=timings)


def _best_views_among_branches(branches: list[Reconstruction]) -> list[Reconstruction]:
    """Each branch with its best next view (recon.pose.optimal_view) chosen with the tree's other
    branches as the vessels it must not overlap."""
    shapes = [(rec.centerline_3d.X_world, rec.profile.smooth_radius_at(rec.centerline_3d.s_mm))
              for rec in branches]
    return [replace(rec, optimal_view=optimal_view(
        *shapes[k], rec.view_a, {"a": rec.view_a, "b": rec.view_b},
        others=tuple(shapes[:k] + shapes[k + 1:]))) for k, rec in enumerate(branches)]


def _with_tree_ffr(seeds: Seeds, branches: list[Reconstruction],
                   options: ReconstructionOptions) -> list[Reconstruction]:
    """Each branch with its FFR solved over the whole tree (recon.lumen.ffr): the flow splits
    at each bifurcation, a branch's pullback (from its carina) starts at its parent's
    pressure where it leaves the parent; the interval pairs draw k of every branch."""
    vessels = []
    for k, rec in enumerate(branches):
        seg = seeds.segments[k]
        parent = None if seg.parent is None else seeds.segment_index(seg.parent)
        join_s = 0.0 if parent is None else nearest_on_polyline(
            branches[parent].centerline_3d.X_world, rec.centerline_3d.X_world[0])[1]
        draws = () if rec.intervals is None else tuple(Lumen.from_profile(p)
                                                       for p in rec.intervals.profiles)
        vessels.append(FFRVessel(Lumen.from_profile(rec.profile), parent, join_s, draws,
                                 seg.name))
    try:
        results = tree_ffr(vessels, ffr_model(options))
    except FFRError as err:  # the QCA stands; no FFR, and the tree's report says why
        note = f"FFR not computed: {err}"
        return [replace(rec, ffr=None, warnings=(*rec.warnings, note)) for rec in branches]
    return [replace(rec, ffr=result) for rec, result in zip(branches, results, strict=True)]


#: Reliability given to a traced point whose lumen another segment's lumen overlaps in
#: that view (below recon.correspond.triangulation.OVERLAP_RELIABILITY: the other view's radius is
#: used there when that view is clear).
TREE_OVERLAP_RELIABILITY = 0.05
#: Two lumen discs overlap when their centres are closer than this fraction of the sum of
#: their radii (1: touching; lumens that only touch or graze leave the fit nearly intact).
TREE_OVERLAP_FRACTION = 0.5


def _overlapped(cl: Centerline2D, others: list[Centerline2D]) -> np.ndarray:
    """(N,) bool: the points of ``cl`` whose lumen disc (centre, radius px) meets the lumen
    disc of a point of another segment's trace in the same view."""
    hit = np.zeros(len(cl.points_px), dtype=bool)
    for other in others:
        gap = np.linalg.norm(cl.points_px[:, None, :] - other.points_px[None, :, :], axis=2)
        reach = TREE_OVERLAP_FRACTION * (cl.radius_px[:, None] + other.radius_px[None, :])
        hit |= np.any(gap < reach, axis=1)
    return hit


def _mark_tree_overlaps(traced: list[tuple[Centerline2D, Centerline2D]]
                        ) -> list[tuple[Centerline2D, Centerline2D]]:
    """Every segment's traces with the reliability lowered where another segment of the
    tree overlaps its lumen in that view, so that the view where the two lumens are
    apart gives the radius there (recon.correspond.triangulation, step 5)."""
    out = []
    for k, pair in enumerate(traced):
        marked = []
        for v, cl in enumerate(pair):
            hit = _overlapped(cl, [traced[j][v] for j in range(len(traced)) if j != k])
            rel = np.where(hit, np.minimum(cl.reliability, TREE_OVERLAP_RELIABILITY),
                           cl.reliability)
            marked.append(replace(cl, reliability=rel))
        out.append((marked[0], marked[1]))
    return out


#: Consecutive points that must be clear of the parent's lumen where a branch's trace
#: leaves it (:func:`_first_clear`).
CLEAR_RUN = 3
#: Farthest (px) the epipolar line of the point where a branch's trace leaves its parent
#: may pass from the other view's trace of the branch (the calibrated pose fits the
#: clicks to about a pixel).
ORIGIN_MATCH_PX = 2.0


def _first_clear(cl: Centerline2D, parent: Centerline2D) -> int | None:
    """Index of the first of :data:`CLEAR_RUN` consecutive points of a branch's trace whose
    lumen is clear of the parent's (centre farther from the parent's trace than the two
    radii together), or None when the trace never clears it."""
    gap = np.linalg.norm(cl.points_px[:, None, :] - parent.points_px[None, :, :], axis=2)
    nearest = np.argmin(gap, axis=1)
    clear = gap[np.arange(len(gap)), nearest] >= parent.radius_px[nearest] + cl.radius_px
    run = np.convolve(clear.astype(int), np.ones(CLEAR_RUN, dtype=int), "valid") == CLEAR_RUN
    return int(np.flatnonzero(run)[0]) if run.any() else None


@dataclass(frozen=True)
class OriginMismatch:
    """A branch's trace in ``view`` ("A" or "B") that runs ``along_px`` along its parent
    and leaves it at a point whose epipolar line misses the other view's trace of the
    branch by ``miss_px``."""

    view: str
    along_px: float
    miss_px: float

    def warning(self, bifurcation: str, branch: str, parent: str) -> str:
        """The one-line warning of the bifurcation (its ``origin_warning``)."""
        return fill_names(self.form(bifurcation), parent, branch)

    def form(self, bifurcation: str) -> str:
        """:meth:`warning` with ``{parent}`` and ``{branch}`` left to fill."""
        other = "B" if self.view == "A" else "A"
        return (f"{literal(bifurcation)}: in view {self.view} the trace of {{branch}} runs "
                f"{self.along_px:.0f} px along {{parent}} and leaves it where view {other}'s "
                f"trace of {{branch}} has no match ({self.miss_px:.1f} px off its epipolar "
                f"line), so its angle and ostium are uncertain; add a waypoint on {{branch}} "
                f"just past its origin in view {self.view}")


@dataclass(frozen=True)
class OriginUnseen:
    """A branch whose trace clears its parent's projected lumen in neither view."""

    def warning(self, bifurcation: str, branch: str, parent: str) -> str:
        """The one-line warning of the bifurcation (its ``origin_warning``)."""
        return fill_names(self.form(bifurcation), parent, branch)

    def form(self, bifurcation: str) -> str:
        """:meth:`warning` with ``{parent}`` and ``{branch}`` left to fill."""
        return (f"{literal(bifurcation)}: {{branch}} does not part from {{parent}}'s shadow "
                "in either view, so where it leaves {parent}, its angle and its ostium are "
                "uncertain; a view in which the two vessels part would settle them")


def _origin_from_the_clear_view(pair: tuple[Centerline2D, Centerline2D],
                                parent: tuple[Centerline2D, Centerline2D],
                                view_a: ViewGeometry, view_b: ViewGeometry
                                ) -> tuple[tuple[Centerline2D, Centerline2D],
                                           OriginMismatch | OriginUnseen | None]:
    """A branch's traces with the origin stretch of a view where the branch runs inside
    its parent's projected lumen redrawn from the other view.

    In view v the trace is taken to run along the parent's lumen when it needs more
    than twice the two lumens' width (parent's radius + branch's, px, at the origin)
    of arc to become clear of it (:func:`_first_clear`, at point S). If the other
    view's trace is clear where it meets the epipolar line of S (point S'), the
    stretch is redrawn from that view: the 3D points on the other view's rays
    through its trace from the origin to S', their distance from its source
    interpolated by arc length between the triangulated origin and the
    triangulated (S, S'), projected into view v and resampled to the stretch's
    point count. Their reliability is lowered, so the radius there is the other
    view's (recon.correspond.triangulation, step 5).

    When S's epipolar line misses the other view's trace by more than
    :data:`ORIGIN_MATCH_PX`, S is on no point of the branch that view sees: view v's
    trace most likely followed the parent instead of a faint origin. Nothing is
    redrawn and the mismatch is returned for the bifurcation's warning; so is
    :class:`OriginUnseen` when neither view's trace clears the parent's lumen (else
    None).
    """
    views = (view_a, view_b)
    out = list(pair)
    mismatch = None
    seps = [_first_clear(pair[v], parent[v]) for v in (0, 1)]
    if seps[0] is None and seps[1] is None:
        return pair, OriginUnseen()
    if seps[0] is None or seps[1] is None:
        return pair, None
    for v in (0, 1):
        o = 1 - v
        cl, other = pair[v], pair[o]
        i_sep = seps[v]
        n0 = int(np.argmin(np.linalg.norm(parent[v].points_px - cl.points_px[0], axis=1)))
        width_px = float(parent[v].radius_px[n0] + cl.radius_px[0])
        if arclength(cl.points_px)[i_sep] < 2.0 * width_px:
            continue  # the branch leaves its parent as a branch does: nothing to redraw
        src_v = views[v].source_world
        ray = views[v].ray_directions(cl.points_px[i_sep][None])[0]
        reach = views[v].sod_mm * np.linspace(0.7, 1.3, 400)
        line = views[o].project(src_v + reach[:, None] * ray)
        dist = point_polyline_distance(other.points_px, line)
        j_sep = int(np.argmin(dist[: max(len(dist) // 2, 4)]))
        if dist[j_sep] > ORIGIN_MATCH_PX:
            mismatch = OriginMismatch("AB"[v], float(arclength(cl.points_px)[i_sep]),
                                      float(dist[j_sep]))
            continue
        if j_sep <= seps[o]:
            continue  # the other view is inside the parent's lumen there too
        ends_v, ends_o = cl.points_px[[0, i_sep]], other.points_px[[0, j_sep]]
        X = triangulate(*((ends_v, ends_o) if v == 0 else (ends_o, ends_v)), view_a, view_b)
        src_o = views[o].source_world
        s_o = arclength(other.points_px[: j_sep + 1])
        f = s_o / max(float(s_o[-1]), 1e-9)
        d0, d1 = np.linalg.norm(X - src_o, axis=1)
        X_o = src_o + ((1.0 - f) * d0 + f * d1)[:, None] * views[o].ray_directions(
            other.points_px[: j_sep + 1])
        q = views[v].project(X_o)
        s_q = arclength(q)
        t = np.linspace(0.0, float(s_q[-1]), i_sep + 1)
        points = cl.points_px.copy()
        points[: i_sep + 1] = np.column_stack([np.interp(t, s_q, q[:, 0]),
                                               np.interp(t, s_q, q[:, 1])])
        reliability = cl.reliability.copy()
        reliability[: i_sep + 1] = np.minimum(reliability[: i_sep + 1], TREE_OVERLAP_RELIABILITY)
        out[v] = replace(cl, points_px=points, reliability=reliability)
    return (out[0], out[1]), mismatch


def _trace_both(angio_a: Angiogram, angio_b: Angiogram, seg: Segment,
                vesselness: tuple[VesselnessMap, VesselnessMap], options: ReconstructionOptions,
                n_segments: int, pose: tuple[ViewGeometry, float, tuple] | None = None,
                ) -> tuple[Centerline2D, Centerline2D]:
    """One segment's traces in A and B; in a tree, a failure names the segment. ``pose``:
    B's pose from the clicks, its tolerance (px) and the views' evidence (computed once for
    the tree), for the 3D tracer (None: 2D)."""
    view_a, view_b = angio_a.geometry, angio_b.geometry
    try:
        if pose is not None:
            return trace_in_3d((angio_a, angio_b), (seg.a, seg.b), vesselness, view_a, pose[0],
                               (options.intensity_a, options.intensity_b), pose[1],
                               pose[2]).traced
        return trace_pair((angio_a, angio_b), (seg.a, seg.b), vesselness,
                           (view_a.pixel_mm_at_isocenter, view_b.pixel_mm_at_isocenter),
                           (options.intensity_a, options.intensity_b))
    except CoronaryError as err:
        if n_segments == 1:
            raise
        named = f"segment {seg.name!r}: {err}"
        if isinstance(err, TraceError):  # its view and place stay (the viewer rings them)
            raise TraceError(named, view=err.view, near_px=err.near_px) from err
        raise PipelineError(named) from err


def _ms(since: float) -> float:
    return round((time.perf_counter() - since) * 1000.0, 2)


def _from_carina(rec: Reconstruction, junction: Junction) -> Reconstruction:
    """A branch's profile and measurements from its carina on (the stretch before
    lies inside the parent's lumen), its ostium zone marked (a narrowing there is a
    lesion only with the profile's support past it, :mod:`recon.lumen.measure`); arc
    lengths stay the branch's own. Its 95 %
    intervals are sampled from the pose posterior of ``rec.calibration`` (the tree's)
    and measured the same way, from the carina on (none without a posterior)."""
    cl = rec.centerline_3d
    s_c = carina_s_mm(cl.X_world, junction.parent_X_world, junction.parent_radius_mm)
    keep = cl.s_mm >= s_c
    ostium = None
    if np.count_nonzero(keep) < 12:  # too short beyond the carina: the whole branch
        s_c, keep = float(cl.s_mm[0]), np.ones(len(cl.s_mm), dtype=bool)
    else:  # where the parent's lumen confounds the branch's radii (recon.lumen.lesions)
        area = rec.surface.sections.area_mm2
        ostium = ostium_zone_end_s_mm(
            cl.X_world, cl.s_mm, float(np.median(np.sqrt(area[keep] / np.pi))),
            junction.parent_X_world, junction.parent_radius_mm, (rec.view_a, rec.view_b), s_c)
    profile = lumen_profile(cl.s_mm[keep], rec.surface.sections.area_mm2[keep],
                            ostium_end_s_mm=ostium)
    measurements = measure_lumen(profile)
    intervals = None
    calibration = rec.calibration
    if calibration.posterior is not None:
        flagged = (None, None) if rec.consistency is None else (
            rec.consistency.a.flagged, rec.consistency.b.flagged)
        intervals = measurement_intervals(rec.view_a, rec.view_b_header, calibration.posterior,
                                          cl, measurements, flagged_a=flagged[0],
                                          flagged_b=flagged[1], measure_from_s_mm=s_c,
                                          ostium_end_s_mm=ostium)
    return replace(rec, profile=profile, measurements=measurements, intervals=intervals)


def _profile_on(rec: Reconstruction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(s, smoothed diameter, reference) (M,) over the whole centerline of a branch.

    The part before a branch's carina (no profile there) takes the first
    profile values.
    """
    s = rec.centerline_3d.s_mm
    p = rec.profile
    d = np.interp(s, p.s_mm, p.diameter_smooth_mm)
    ref = np.interp(s, p.s_mm, p.reference_diameter_mm)
    return s, d, ref


def _bifurcation(seeds: Seeds, branches: list[Reconstruction], k: int,
                 mismatch: OriginMismatch | OriginUnseen | None = None) -> BifurcationQCA:
    """Segment k's bifurcation QCA; its origin warning from ``mismatch`` where the QCA's
    own check has none."""
    seg = seeds.segments[k]
    parent = branches[seeds.segment_index(seg.parent)]
    branch = branches[k]
    shift = float(np.linalg.norm(branch.centerline_3d.X_world[0]
                                 - _unjoined_start(branch)))
    qca = bifurcation_qca(
        seg.bifurcation, seg.parent, seg.name,
        parent.centerline_3d.X_world, _profile_on(parent),
        branch.centerline_3d.X_world, _profile_on(branch), shift,
    )
    if mismatch is not None and qca.origin_warning is None:
        qca = replace(qca, origin_warning=mismatch.warning(seg.bifurcation, seg.name,
                                                           seg.parent),
                      origin_form=mismatch.form(seg.bifurcation))
    return qca


def _unjoined_start(rec: Reconstruction) -> np.ndarray:
    """Where the branch began before the join, to within the smoothing: its first
    triangulated (raw) point."""
    return rec.centerline_3d.X_raw_world[0]
