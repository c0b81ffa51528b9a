"""Cross-view consistency: does the 3D centerline agree with both images?

After triangulation the 3D centerline is projected back into each view and
compared with what that view shows:

- **On the vessel.** Each projected point's distance to that view's 2D trace
  (px), and the vesselness at the projected point relative to the vesselness
  along the trace nearby. Triangulation only enforces the epipolar
  constraint, so a trace that wandered across the epipolar lines (onto a
  neighbour) leaves the projection off it.
- **Arc length between the marks.** Between two consecutive clicks of a view,
  the trace's 2D arc length is compared with the 2D arc length of the
  projected 3D curve between the same two clicks. Both are measured in the
  same image, so foreshortening (which the 3D curve carries) cancels: a trace
  that detoured along another vessel is longer than the projection.
- **Local detours.** The same comparison in short windows: where the trace
  ran out along a side branch and came back, the projection stays near the
  trace but the trace's arc position jumps.
- **Overlaps the other view cannot check.** Where a view's trace crosses or
  touches another vessel's shadow, or bends too tightly for a straight-tube fit,
  its profile fits are unreliable and the trace is bridged there from either
  side. Where the vessel also crosses that view's epipolar lines, a sideways
  error of the bridge lies along them: it moves the 3D point along the other
  view's ray, which that view cannot see. Such a stretch is listed on the
  overlapped view, so its position is never taken silently.
- **Bends one view cannot see.** A detour that runs along the epipolar lines
  is absorbed by triangulation into the other view's depth: the 3D curve then
  bends where its projection into that other view stays straight. A sharp
  3D bend hidden in one view and shown only by the other view's trace is
  flagged on the view whose trace shows it.

Every failing stretch is listed (view, 3D arc-length extent in mm, the 2D
place of its middle, a one-line reason); nothing is silently measured.

Thresholds, with why (see :class:`ConsistencyThresholds`): a consistent pair
projects within ~1-1.5 px of the traces (click noise ~0.7 px, trace error
~0.3 px, calibration residual ~0.5-1 px, the 3D smoothing spline ~0.3 px),
so 3 px (or the traced lumen radius, if larger) is "off the vessel"; arc
lengths between marks agree to ~1-3 % (trace wiggle, the spline cutting
corners), so 10 % (and at least 5 px) is a detour.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage as ndi

from recon.correspond.triangulation import segment_feet_2d
from recon.geometry import ViewGeometry
from recon.types import Centerline2D, Centerline3D, arclength

__all__ = [
    "ConsistencyThresholds",
    "MarkInterval",
    "Stretch",
    "ViewConsistency",
    "ConsistencyResult",
    "check_consistency",
    "check_view",
    "nearest_on_polyline",
    "turning_deg",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class ConsistencyThresholds:
    """When a stretch of the 3D centerline counts as inconsistent with a view.

    offset_px : a projected point farther than this from the trace is off the
        vessel (the larger of this and the traced lumen radius there). 3 px:
        a consistent pair stays within ~1-1.5 px (click noise ~0.7 px, trace
        error ~0.3 px, calibration residual ~0.5-1 px), and 3 px is outside
        the lumen of any vessel under ~6 px across.
    vesselness_ratio : a projected point whose vesselness is below this
        fraction of the trace's (median within ``reference_window_px`` of the
        nearest trace point) is off the vessel. 0.3: across a tube the
        response falls to ~0.6 at half a radius off centre and to ~0.1 one
        radius off; catches thin vessels where 3 px is too lenient.
    arc_length_pct : between two consecutive clicks of a view, the trace's
        arc length may differ from the projected 3D curve's by this much
        (percent of the projected length). 10 %: both are measured in the
        same image between the same clicks, so foreshortening cancels; trace
        wiggle and the spline cutting corners make ~1-3 %.
    arc_length_min_px : and by at least this much (px): short intervals
        between close clicks are not flagged for a pixel or two.
    detour_window_px : window (px of projected arc) of the local detour check.
    detour_excess_px : the trace may be this much longer than the projection
        within one window. 6 px = twice ``offset_px``: a detour that stays
        within the offset threshold yet adds more trace must go out and back.
    bend_deg, bend_window_mm : the 3D curve may turn by this much more than its
        projection into a view does, within a window of this 3D arc. A detour
        in one view's trace that runs along the epipolar lines is not an
        offset: triangulation absorbs it into the other view's depth, as a
        bend that view cannot see. 35 deg over 5 mm: a consistent phantom or
        real pair stays under ~25 deg; a 6 px bulge in a trace makes ~35 deg.
    overlap_reliability : a trace point whose profile-fit reliability
        (:attr:`~recon.types.Centerline2D.reliability`) is below this was bridged
        (an overlapping or touching vessel): a clean tube's fit has 1. 0.05: at 0.3
        two thirds more stretches are listed and hardly more bridges that went wrong
        (docs/benchmarks.md, issue 45).
    overlap_across_deg : such a point is unchecked by the other view where the
        vessel crosses this view's epipolar lines at more than this angle: a
        sideways error is then mostly along the epipolar line (sin 45 deg = 71 %).
    overlap_min_mm : and over at least this much 3D arc (a single bridged fit is
        noise).
    min_stretch_mm : flagged runs shorter than this (3D arc) are dropped as
        single-point noise; runs closer than it are merged.
    end_margin_mm : the first and last few mm of the 3D curve are not checked
        for offset/vesselness (the curve's ends are extrapolated by the
        smoothing spline and the clicks sit where the vessel starts/stops).
    """

    offset_px: float = 3.0
    vesselness_ratio: float = 0.3
    reference_window_px: float = 10.0
    arc_length_pct: float = 10.0
    arc_length_min_px: float = 5.0
    detour_window_px: float = 20.0
    detour_excess_px: float = 6.0
    bend_deg: float = 35.0
    bend_window_mm: float = 5.0
    overlap_reliability: float = 0.05
    overlap_across_deg: float = 45.0
    overlap_min_mm: float = 1.0
    min_stretch_mm: float = 0.75
    end_margin_mm: float = 1.0

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass(frozen=True)
class MarkInterval:
    """Arc lengths between two consecutive clicks of one view (clicks 1-based)."""

    view: str
    from_click: int
    to_click: int
    traced_px: float
    projected_px: float
    start_mm: float
    end_mm: float

    @property
    def ratio(self) -> float:
        """Traced / projected arc length (1 = consistent; > 1: the trace is longer)."""
        return self.traced_px / max(self.projected_px, 1e-9)


@dataclass(frozen=True)
class Stretch:
    """A stretch of the 3D centerline that one view does not support.

    view : "a" or "b".
    kind : "off_vessel", "arc_length", "detour", "depth_bend" or "overlap".
    start_mm, end_mm : extent along the 3D centerline (mm from the proximal end).
    middle_px : (col, row) in that view of the stretch's middle (the projected
        3D point for off_vessel/arc_length, the trace point for detour).
    value : the worst offset (px), the arc-length excess (percent), or the
        window excess (px).
    reason : one line, e.g. "off the vessel in view B by 3.2 px".
    """

    view: str
    kind: str
    start_mm: float
    end_mm: float
    middle_px: tuple[float, float]
    value: float
    reason: str

    def to_dict(self) -> dict:
        return {
            "view": self.view,
            "kind": self.kind,
            "start_mm": round(self.start_mm, 2),
            "end_mm": round(self.end_mm, 2),
            "middle_px": [round(self.middle_px[0], 1), round(self.middle_px[1], 1)],
            "value": round(self.value, 2),
            "reason": self.reason,
        }


@dataclass(frozen=True, eq=False)
class ViewConsistency:
    """The 3D centerline (M points) seen against one view.

    projected_px : (M, 2) the 3D centerline projected into the view.
    offset_px : (M,) distance of each projected point to the trace polyline.
    trace_s_px : (M,) arc position (px from the trace's start) of the nearest
        trace point.
    vesselness_ratio : (M,) vesselness at the projected point over the trace's
        local reference (nan where not checked).
    off_vessel : (M,) bool, flagged by offset or vesselness.
    detour : (M,) bool, inside a window where the trace is longer than the
        projection by more than the threshold.
    arc_length : (M,) bool, inside a click interval whose arc lengths disagree.
    hidden_bend_deg : (M,) how much more the 3D curve turns (within the bend
        window) than its projection into the *other* view does: a bend only
        this view's trace shows.
    depth_bend : (M,) bool, ``hidden_bend_deg`` over the threshold.
    overlap : (M,) bool, the trace bridged over another vessel's shadow where the
        vessel crosses this view's epipolar lines (the other view cannot check it).
    reliability : (M,) the trace's fit reliability at the nearest trace point.
    intervals : the click intervals of this view.
    """

    view: str
    projected_px: FloatArray
    offset_px: FloatArray
    trace_s_px: FloatArray
    vesselness_ratio: FloatArray
    off_vessel: BoolArray
    detour: BoolArray
    arc_length: BoolArray
    hidden_bend_deg: FloatArray | None = None
    depth_bend: BoolArray | None = None
    intervals: tuple[MarkInterval, ...] = field(default_factory=tuple)
    overlap: BoolArray | None = None
    reliability: FloatArray | None = None

    def __post_init__(self) -> None:
        m = len(self.offset_px)
        if self.hidden_bend_deg is None:
            object.__setattr__(self, "hidden_bend_deg", np.zeros(m))
        if self.depth_bend is None:
            object.__setattr__(self, "depth_bend", np.zeros(m, dtype=bool))
        if self.overlap is None:
            object.__setattr__(self, "overlap", np.zeros(m, dtype=bool))
        if self.reliability is None:
            object.__setattr__(self, "reliability", np.ones(m))

    @property
    def flagged(self) -> BoolArray:
        """(M,) bool: any check failed at this point."""
        return (self.off_vessel | self.detour | self.arc_length | np.asarray(self.depth_bend)
                | np.asarray(self.overlap))

    @property
    def max_offset_px(self) -> float:
        return float(np.max(self.offset_px)) if len(self.offset_px) else 0.0


@dataclass(frozen=True, eq=False)
class ConsistencyResult:
    """Both views' checks and the failing stretches."""

    a: ViewConsistency
    b: ViewConsistency
    s_mm: FloatArray
    stretches: tuple[Stretch, ...]
    thresholds: ConsistencyThresholds

    @property
    def ok(self) -> bool:
        return not self.stretches

    @property
    def flagged(self) -> BoolArray:
        """(M,) bool along the 3D centerline: flagged in either view."""
        return self.a.flagged | self.b.flagged

    def to_dict(self) -> dict:
        """The report.json ``consistency`` block."""
        return {
            "ok": self.ok,
            "stretches": [s.to_dict() for s in self.stretches],
            "max_offset_px": {v.view: round(v.max_offset_px, 2) for v in (self.a, self.b)},
            "median_offset_px": {
                v.view: round(float(np.median(v.offset_px)), 2) for v in (self.a, self.b)
            },
            "arc_length_ratio": {
                v.view: [
                    {
                        "clicks": [iv.from_click, iv.to_click],
                        "traced_px": round(iv.traced_px, 1),
                        "projected_px": round(iv.projected_px, 1),
                        "ratio": round(iv.ratio, 3),
                    }
                    for iv in v.intervals
                ]
                for v in (self.a, self.b)
            },
            "thresholds": self.thresholds.to_dict(),
        }


# ------------------------------------------------------------------ geometry
def nearest_on_polyline(
    points_px: FloatArray, polyline_px: FloatArray, chunk: int = 512
) -> tuple[FloatArray, FloatArray]:
    """Distance (M,) of points (M, 2) to a polyline (N, 2) and the arc position (M,)
    (px from the polyline's start) of the nearest point on it."""
    p = np.asarray(points_px, dtype=float).reshape(-1, 2)
    q = np.asarray(polyline_px, dtype=float).reshape(-1, 2)
    s = arclength(q)
    a, d = q[:-1], np.diff(q, axis=0)  # (S, 2) segment starts and vectors
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-18)
    dist = np.empty(len(p))
    pos = np.empty(len(p))
    for lo in range(0, len(p), chunk):
        t, d2 = segment_feet_2d(p[lo:lo + chunk], a, d, dd)  # (C, S) each
        k = np.argmin(d2, axis=1)
        rows = np.arange(len(k))
        dist[lo:lo + chunk] = np.sqrt(d2[rows, k])
        pos[lo:lo + chunk] = s[k] + t[rows, k] * np.sqrt(dd[k])
    return dist, pos


def _sample(image: NDArray, points_px: FloatArray) -> FloatArray:
    """Bilinear samples (N,) of an (H, W) image at (col, row) points (N, 2)."""
    p = np.asarray(points_px, dtype=float).reshape(-1, 2)
    return ndi.map_coordinates(
        np.asarray(image, dtype=np.float32), [p[:, 1], p[:, 0]], order=1, mode="constant"
    ).astype(float)


def _runs(mask: BoolArray) -> list[tuple[int, int]]:
    """(start, stop) inclusive index pairs of the True runs of a (M,) mask."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, stops = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0] - 1
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


def _clean(mask: BoolArray, s_mm: FloatArray, min_mm: float) -> BoolArray:
    """Merge runs closer than ``min_mm`` and drop runs shorter than it."""
    out = mask.copy()
    runs = _runs(out)
    for (_, e0), (s1, _) in zip(runs[:-1], runs[1:], strict=True):
        if s_mm[s1] - s_mm[e0] < min_mm:
            out[e0:s1] = True
    for i, j in _runs(out):
        if s_mm[j] - s_mm[i] < min_mm:
            out[i:j + 1] = False
    return out


def turning_deg(curve: FloatArray, s_mm: FloatArray, window_mm: float) -> FloatArray:
    """Angle (M,) in degrees between the curve's tangents half a window before and
    after each point (clipped at the ends); ``curve`` is (M, D) at arc length ``s_mm``."""
    c = np.asarray(curve, dtype=float)
    t = np.gradient(c, axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    half = window_mm / 2.0
    i0 = np.searchsorted(s_mm, s_mm - half, side="left")
    i1 = np.clip(np.searchsorted(s_mm, s_mm + half, side="right") - 1, 0, len(s_mm) - 1)
    cos = np.clip(np.einsum("ij,ij->i", t[i0], t[i1]), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def _depth_bends(
    X: FloatArray, s: FloatArray, p_other: FloatArray, th: ConsistencyThresholds
) -> tuple[FloatArray, BoolArray]:
    """How much more the 3D curve turns than its projection into the other view (M,),
    and where that exceeds the threshold (M,) bool."""
    hidden = turning_deg(X, s, th.bend_window_mm) - turning_deg(p_other, s, th.bend_window_mm)
    return hidden, _clean(hidden > th.bend_deg, s, th.min_stretch_mm)


def _unchecked_overlaps(
    X: FloatArray, s: FloatArray, geometry: ViewGeometry, other: ViewGeometry,
    vc: ViewConsistency, inner: BoolArray, th: ConsistencyThresholds,
) -> BoolArray:
    """(M,) bool: bridged points of a view's trace (``vc.reliability`` below the
    threshold) where the 3D curve (M, 3) crosses the view's epipolar lines at more than
    the threshold angle, so that the ``other`` view cannot see a sideways error."""
    p = vc.projected_px
    ray = X - other.source_world[None, :]
    ray /= np.maximum(np.linalg.norm(ray, axis=1, keepdims=True), 1e-12)
    epi = geometry.project(X + ray) - p  # the image of the other view's ray: the epipolar line
    tan = np.gradient(p, axis=0)
    cos = np.abs(np.einsum("ij,ij->i", epi, tan)) / np.maximum(
        np.linalg.norm(epi, axis=1) * np.linalg.norm(tan, axis=1), 1e-12)
    across = cos < np.cos(np.radians(th.overlap_across_deg))
    return _clean(inner & across & (vc.reliability < th.overlap_reliability), s,
                  th.overlap_min_mm)


# ------------------------------------------------------------------ one view
def check_view(
    view: str,
    X_world: FloatArray,
    s_mm: FloatArray,
    geometry: ViewGeometry,
    trace: Centerline2D,
    response: NDArray | None = None,
    thresholds: ConsistencyThresholds | None = None,
) -> ViewConsistency:
    """Check the 3D centerline (M, 3) against one view's trace and vesselness.

    Parameters
    ----------
    view : "a" or "b" (names the view in the result).
    X_world : (M, 3) 3D centerline, proximal to distal, world mm.
    s_mm : (M,) its arc length.
    geometry : the view's (calibrated) geometry.
    trace : the view's traced :class:`Centerline2D` (its ``clicks_px`` are the marks).
    response : (H, W) the view's vesselness response (``VesselnessMap.response``);
        None skips the vesselness check.
    """
    th = thresholds or ConsistencyThresholds()
    X = np.asarray(X_world, dtype=float).reshape(-1, 3)
    s = np.asarray(s_mm, dtype=float).ravel()
    m = len(X)
    p = geometry.project(X)
    offset, t_pos = nearest_on_polyline(p, trace.points_px)
    s_trace = trace.arclength_px
    inner = (s >= s[0] + th.end_margin_mm) & (s <= s[-1] - th.end_margin_mm)

    # On the vessel: distance to the trace (at least the traced lumen radius), vesselness.
    radius_at = np.interp(t_pos, s_trace, trace.radius_px)
    off = inner & (offset > np.maximum(th.offset_px, radius_at))
    ratio = np.full(m, np.nan)
    if response is not None:
        # local reference: the trace's response, median over +-window (the trace is at
        # roughly uniform spacing), at the nearest trace point
        v_trace = _sample(response, trace.points_px)
        step = max(float(s_trace[-1]) / max(len(s_trace) - 1, 1), 1e-6)
        size = 2 * int(round(th.reference_window_px / step)) + 1
        v_ref = ndi.median_filter(v_trace, size=min(size, 2 * (len(v_trace) // 2) + 1),
                                  mode="nearest")
        ref = np.interp(t_pos, s_trace, v_ref)
        v_proj = _sample(response, p)
        ratio = np.where(ref > 1e-6, v_proj / np.maximum(ref, 1e-6), 1.0)
        ratio[~inner] = np.nan
        off |= inner & (ratio < th.vesselness_ratio)
    off = _clean(off, s, th.min_stretch_mm)

    # Local detours: within a window of projected arc, the trace covers much more arc.
    # A median over ~9 points ignores the brief forward jump of the nearest trace
    # point where the curve crosses itself in projection (the jump reverts there,
    # while a detour's stays).
    sp = arclength(p)
    t_robust = ndi.median_filter(t_pos, size=min(9, 2 * (m // 2) - 1 if m > 2 else 1),
                                 mode="nearest")
    j_end = np.searchsorted(sp, sp + th.detour_window_px, side="right") - 1
    excess = (t_robust[j_end] - t_robust) - (sp[j_end] - sp)
    detour = np.zeros(m, dtype=bool)
    for i in np.nonzero(excess > th.detour_excess_px)[0]:
        detour[i:j_end[i] + 1] = True

    # Arc length between consecutive clicks: traced vs projected.
    intervals: list[MarkInterval] = []
    arc_bad = np.zeros(m, dtype=bool)
    clicks = np.asarray(trace.clicks_px, dtype=float).reshape(-1, 2)
    if len(clicks) >= 2:
        _, t_click = nearest_on_polyline(clicks, trace.points_px)
        m_click = np.argmin(np.linalg.norm(p[None] - clicks[:, None], axis=2), axis=1)
        for k in range(len(clicks) - 1):
            i, j = sorted((int(m_click[k]), int(m_click[k + 1])))
            iv = MarkInterval(
                view=view, from_click=k + 1, to_click=k + 2,
                traced_px=float(abs(t_click[k + 1] - t_click[k])),
                projected_px=float(sp[j] - sp[i]),
                start_mm=float(s[i]), end_mm=float(s[j]),
            )
            intervals.append(iv)
            diff = iv.traced_px - iv.projected_px
            if abs(diff) > max(th.arc_length_pct / 100.0 * iv.projected_px, th.arc_length_min_px):
                arc_bad[i:j + 1] = True
    reliability = (np.ones(m) if trace.reliability is None
                   else np.interp(t_pos, s_trace, np.asarray(trace.reliability, dtype=float)))
    return ViewConsistency(
        view=view, projected_px=p, offset_px=offset, trace_s_px=t_pos,
        vesselness_ratio=ratio, off_vessel=off, detour=detour, arc_length=arc_bad,
        intervals=tuple(intervals), reliability=reliability,
    )


def _stretches(vc: ViewConsistency, s: FloatArray, trace: Centerline2D) -> list[Stretch]:
    """The failing stretches of one view, with one-line reasons."""
    name = vc.view.upper()
    out: list[Stretch] = []
    for i, j in _runs(vc.off_vessel):
        worst = i + int(np.argmax(vc.offset_px[i:j + 1]))
        mid = (i + j) // 2
        low = np.nanmin(vc.vesselness_ratio[i:j + 1]) if np.any(
            np.isfinite(vc.vesselness_ratio[i:j + 1])) else np.nan
        why = f"off the vessel in view {name} by {vc.offset_px[worst]:.1f} px"
        if np.isfinite(low) and low < 1.0:
            why += f" (vesselness {100 * low:.0f} % of the trace's)"
        out.append(Stretch(vc.view, "off_vessel", float(s[i]), float(s[j]),
                           tuple(float(x) for x in vc.projected_px[mid]),
                           float(vc.offset_px[worst]), why))
    for iv in vc.intervals:
        i = int(np.searchsorted(s, iv.start_mm))
        if not vc.arc_length[min(i, len(s) - 1)]:
            continue
        j = int(np.searchsorted(s, iv.end_mm))
        mid = (i + j) // 2
        pct = 100.0 * (iv.ratio - 1.0)
        word = "longer" if pct > 0 else "shorter"
        why = (f"arc length in {name} {abs(pct):.0f} % {word} than the 3D curve's projection "
               f"between click {iv.from_click} and click {iv.to_click} "
               f"({iv.traced_px:.0f} px traced, {iv.projected_px:.0f} px projected)")
        out.append(Stretch(vc.view, "arc_length", iv.start_mm, iv.end_mm,
                           tuple(float(x) for x in vc.projected_px[mid]), pct, why))
    s_trace = trace.arclength_px
    for i, j in _runs(vc.detour):
        if vc.off_vessel[i:j + 1].any():
            continue  # the same place is already off the vessel (a wide detour)
        extra = float((vc.trace_s_px[j] - vc.trace_s_px[i]) - (
            arclength(vc.projected_px[i:j + 1])[-1]))
        t_mid = 0.5 * (vc.trace_s_px[i] + vc.trace_s_px[j])
        mid_px = np.array([np.interp(t_mid, s_trace, trace.points_px[:, c]) for c in (0, 1)])
        why = (f"the trace in view {name} detours: {extra:.0f} px more trace than the 3D "
               f"curve's projection between {s[i]:.1f} and {s[j]:.1f} mm; add a waypoint there")
        out.append(Stretch(vc.view, "detour", float(s[i]), float(s[j]),
                           (float(mid_px[0]), float(mid_px[1])), extra, why))
    other = "B" if vc.view == "a" else "A"
    for i, j in _runs(np.asarray(vc.depth_bend)):
        if vc.off_vessel[i:j + 1].any() or vc.detour[i:j + 1].any():
            continue
        worst = i + int(np.argmax(vc.hidden_bend_deg[i:j + 1]))
        why = (f"the 3D curve bends {vc.hidden_bend_deg[worst]:.0f} deg more than view "
               f"{other} shows between {s[i]:.1f} and {s[j]:.1f} mm: only view {name}'s "
               f"trace bends there; if it left the vessel, add a waypoint in {name} there")
        out.append(Stretch(vc.view, "depth_bend", float(s[i]), float(s[j]),
                           tuple(float(x) for x in vc.projected_px[worst]),
                           float(vc.hidden_bend_deg[worst]), why))
    for i, j in _runs(np.asarray(vc.overlap)):
        if (vc.off_vessel[i:j + 1].any() or vc.detour[i:j + 1].any()
                or np.asarray(vc.depth_bend)[i:j + 1].any()):
            continue  # the place is already listed
        mid = (i + j) // 2
        why = (f"view {name}'s trace is bridged between {s[i]:.1f} and {s[j]:.1f} mm (no "
               f"clean single-tube fit there: another vessel's shadow or a tight bend), "
               f"across the epipolar lines, so view {other} cannot check its position; "
               f"check the trace there, or add a waypoint in {name} on the vessel's centre")
        out.append(Stretch(vc.view, "overlap", float(s[i]), float(s[j]),
                           tuple(float(x) for x in vc.projected_px[mid]),
                           float(np.min(np.asarray(vc.reliability)[i:j + 1])), why))
    return out


def check_consistency(
    centerline_3d: Centerline3D,
    view_a: ViewGeometry,
    view_b: ViewGeometry,
    trace_a: Centerline2D,
    trace_b: Centerline2D,
    response_a: NDArray | None = None,
    response_b: NDArray | None = None,
    thresholds: ConsistencyThresholds | None = None,
) -> ConsistencyResult:
    """Check the 3D centerline against both views (see the module docstring).

    Parameters
    ----------
    centerline_3d : the triangulated, smoothed centerline (M points).
    view_a, view_b : the geometries it was triangulated with (B calibrated).
    trace_a, trace_b : the two traced centerlines (with their snapped clicks).
    response_a, response_b : (H, W) vesselness responses, or None to skip that check.

    Returns
    -------
    ConsistencyResult with per-point flags per view and the failing stretches,
    ordered by view then position.
    """
    th = thresholds or ConsistencyThresholds()
    X, s = centerline_3d.X_world, centerline_3d.s_mm
    va = check_view("a", X, s, view_a, trace_a, response_a, th)
    vb = check_view("b", X, s, view_b, trace_b, response_b, th)
    # a bend hidden in view A is shown only by B's trace: it is B's stretch, and vice versa
    bend_b = _depth_bends(X, s, va.projected_px, th)
    bend_a = _depth_bends(X, s, vb.projected_px, th)
    inner = (s >= s[0] + th.end_margin_mm) & (s <= s[-1] - th.end_margin_mm)
    over_a = _unchecked_overlaps(X, s, view_a, view_b, va, inner, th)
    over_b = _unchecked_overlaps(X, s, view_b, view_a, vb, inner, th)
    va = replace(va, hidden_bend_deg=bend_a[0], depth_bend=bend_a[1], overlap=over_a)
    vb = replace(vb, hidden_bend_deg=bend_b[0], depth_bend=bend_b[1], overlap=over_b)
    stretches = _stretches(va, s, trace_a) + _stretches(vb, s, trace_b)
    stretches.sort(key=lambda st: (st.view, st.start_mm))
    return ConsistencyResult(a=va, b=vb, s_mm=np.asarray(s, dtype=float),
                             stretches=tuple(stretches), thresholds=th)
