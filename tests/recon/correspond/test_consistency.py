"""Cross-view consistency (recon.correspond.consistency) on synthetic cases with known answers.

A smooth 3D vessel is projected into two C-arm views; the traces are its
exact projections (a consistent pair) or view B's trace is bent off along a
neighbouring vessel over a known stretch (a detour). The vesselness maps are
Gaussian ridges rendered along the drawn vessels, the neighbour included, so
a detour runs on a vessel, as it does on a real image.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import ndimage as ndi

from recon.correspond.consistency import (
    ConsistencyThresholds,
    check_consistency,
    nearest_on_polyline,
)
from recon.geometry import ViewGeometry, epipolar_lines
from recon.types import Centerline2D, Centerline3D, arclength

VIEW_A = ViewGeometry(0.0, 0.0, 1000.0, 750.0, (0.3, 0.3), 512, 512)
VIEW_B = ViewGeometry(50.0, 15.0, 1000.0, 750.0, (0.3, 0.3), 512, 512)


def vessel_3d(spacing_mm: float = 0.25) -> Centerline3D:
    """A gently curving 3D vessel (~70 mm) at uniform arc length."""
    t = np.linspace(0.0, 1.0, 4000)
    X = np.stack([-30 + 60 * t, 20 * np.sin(2.2 * t), 12 * np.cos(3.0 * t) - 6], axis=1)
    s = arclength(X)
    s_new = np.arange(0.0, s[-1], spacing_mm)
    X = np.stack([np.interp(s_new, s, X[:, k]) for k in range(3)], axis=1)
    tang = np.gradient(X, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    m = len(X)
    return Centerline3D(
        X_world=X, s_mm=s_new, tangents=tang, radius_a_mm=np.full(m, 1.0),
        radius_b_mm=np.full(m, 1.0), X_raw_world=X, points_a_px=VIEW_A.project(X),
        points_b_px=VIEW_B.project(X),
    )


def resample(points_px: np.ndarray, spacing_px: float = 0.5) -> np.ndarray:
    s = arclength(points_px)
    s_new = np.linspace(0.0, s[-1], int(s[-1] / spacing_px) + 1)
    return np.column_stack([np.interp(s_new, s, points_px[:, k]) for k in (0, 1)])


def trace(points_px: np.ndarray, clicks_px: np.ndarray, radius_px: float = 2.5) -> Centerline2D:
    pts = resample(points_px)
    n = len(pts)
    _, at = nearest_on_polyline(clicks_px, pts)
    on = np.column_stack([np.interp(at, arclength(pts), pts[:, k]) for k in (0, 1)])
    return Centerline2D(points_px=pts, radius_px=np.full(n, radius_px),
                        brightness=np.zeros(n), clicks_px=on)


def ridge_response(curves: list[np.ndarray], shape=(512, 512), sigma_px: float = 2.0
                   ) -> np.ndarray:
    """(H, W) vesselness-like response: 1 on the drawn curves, Gaussian across."""
    mask = np.zeros(shape, dtype=bool)
    for c in curves:
        p = resample(c, 0.25)
        ij = np.round(p[:, ::-1]).astype(int)
        ok = (ij >= 0).all(1) & (ij[:, 0] < shape[0]) & (ij[:, 1] < shape[1])
        mask[ij[ok, 0], ij[ok, 1]] = True
    d = ndi.distance_transform_edt(~mask)
    return np.exp(-0.5 * (d / sigma_px) ** 2).astype(np.float32)


def bump(points_px: np.ndarray, lo: float, hi: float, height_px: float) -> np.ndarray:
    """The curve with its stretch between arc fractions lo..hi bent off sideways by up
    to ``height_px`` (a smooth sin^2 bulge along the normal): a detour."""
    pts = resample(points_px, 0.5)
    s = arclength(pts) / arclength(pts)[-1]
    t = np.gradient(pts, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    n = np.column_stack([-t[:, 1], t[:, 0]])
    w = np.where((s > lo) & (s < hi), np.sin(np.pi * (s - lo) / (hi - lo)) ** 2, 0.0)
    return pts + height_px * w[:, None] * n


def consistent_case():
    c3 = vessel_3d()
    pa, pb = VIEW_A.project(c3.X_world), VIEW_B.project(c3.X_world)
    ta = trace(pa, pa[[0, -1]])
    tb = trace(pb, pb[[0, len(pb) // 2, -1]])  # a waypoint in B
    return c3, pa, pb, ta, tb


def test_nearest_on_polyline_distances_and_positions() -> None:
    poly = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    pts = np.array([[5.0, 3.0], [12.0, 5.0], [-3.0, -4.0], [10.0, 10.0]])
    dist, pos = nearest_on_polyline(pts, poly, chunk=2)
    assert np.allclose(dist, [3.0, 2.0, 5.0, 0.0])
    assert np.allclose(pos, [5.0, 15.0, 0.0, 20.0])


def test_a_consistent_pair_passes() -> None:
    c3, pa, pb, ta, tb = consistent_case()
    ra, rb = ridge_response([pa]), ridge_response([pb])
    result = check_consistency(c3, VIEW_A, VIEW_B, ta, tb, ra, rb)
    assert result.ok, [s.reason for s in result.stretches]
    assert not result.flagged.any()
    assert result.a.max_offset_px < 0.1 and result.b.max_offset_px < 0.1
    assert len(result.a.intervals) == 1 and len(result.b.intervals) == 2
    for iv in result.a.intervals + result.b.intervals:
        assert abs(iv.ratio - 1.0) < 0.01
    assert np.nanmin(result.b.vesselness_ratio) > 0.9
    report = json.loads(json.dumps(result.to_dict()))
    assert report["ok"] is True and report["stretches"] == []
    assert set(report["max_offset_px"]) == {"a", "b"}
    assert [iv["clicks"] for iv in report["arc_length_ratio"]["b"]] == [[1, 2], [2, 3]]


def test_a_calibration_residual_of_two_px_is_not_flagged() -> None:
    c3, pa, pb, ta, _ = consistent_case()
    shifted = pb + np.array([1.4, -1.4])  # 2 px off everywhere, like a calibration residual
    tb = trace(shifted, shifted[[0, -1]])
    result = check_consistency(c3, VIEW_A, VIEW_B, ta, tb, ridge_response([pa]),
                               ridge_response([shifted]))
    assert result.ok, [s.reason for s in result.stretches]
    assert 1.9 < np.median(result.b.offset_px) < 2.1


def test_a_detour_in_b_is_flagged_at_the_right_place() -> None:
    c3, pa, pb, ta, _ = consistent_case()
    lo, hi = 0.45, 0.65
    detour = bump(pb, lo, hi, height_px=14.0)
    tb = trace(detour, detour[[0, -1]])
    # the detour follows a neighbouring vessel: both are vessels in B's vesselness
    result = check_consistency(c3, VIEW_A, VIEW_B, ta, tb, ridge_response([pa]),
                               ridge_response([pb, detour]))
    assert not result.ok
    assert result.a.flagged.sum() == 0  # view A is fine
    off = [s for s in result.stretches if s.kind == "off_vessel"]
    assert len(off) == 1 and off[0].view == "b"
    st = off[0]
    assert st.reason.startswith("off the vessel in view B by ")
    assert 12.0 < st.value <= 14.5
    # the detoured stretch of the 3D curve: where B's 2D arc fraction is in lo..hi
    frac = arclength(pb) / arclength(pb)[-1]
    s_lo, s_hi = np.interp([lo, hi], frac, c3.s_mm)
    assert s_lo - 1.0 < st.start_mm < st.end_mm < s_hi + 1.0
    assert st.end_mm - st.start_mm > 0.5 * (s_hi - s_lo)
    # its middle is at the middle of the bulge on the 3D curve's projection
    mid = np.interp(0.5 * (lo + hi), frac, np.arange(len(pb)))
    assert np.linalg.norm(np.array(st.middle_px) - pb[int(round(mid))]) < 4.0
    # the trace between the two clicks is longer than the projection
    (iv,) = result.b.intervals
    assert iv.ratio > 1.02
    assert result.to_dict()["max_offset_px"]["b"] > 12.0


def test_a_long_detour_fails_the_arc_length_between_clicks() -> None:
    c3, pa, pb, ta, _ = consistent_case()
    detour = bump(pb, 0.3, 0.7, height_px=60.0)
    tb = trace(detour, detour[[0, -1]])
    result = check_consistency(c3, VIEW_A, VIEW_B, ta, tb, ridge_response([pa]),
                               ridge_response([pb, detour]))
    arc = [s for s in result.stretches if s.kind == "arc_length"]
    assert len(arc) == 1 and arc[0].view == "b"
    (iv,) = result.b.intervals
    assert iv.ratio > 1.1
    assert arc[0].reason.startswith(
        f"arc length in B {100 * (iv.ratio - 1):.0f} % longer than the 3D curve's projection "
        "between click 1 and click 2")


def test_out_and_back_along_a_side_branch_is_a_detour() -> None:
    """The trace runs 10 px up a side branch and back: it stays within 3 px of the
    projection everywhere (no offset flag) but has 20 px more arc at the branch."""
    c3, pa, pb, ta, _ = consistent_case()
    k = len(pb) // 2
    t = pb[k + 1] - pb[k - 1]
    n = np.array([-t[1], t[0]]) / np.linalg.norm(t)
    spur = pb[k] + np.linspace(0.0, 10.0, 21)[:, None] * n
    path = np.vstack([pb[:k], spur, spur[::-1][1:], pb[k + 1:]])
    tb = trace(path, pb[[0, -1]])
    result = check_consistency(c3, VIEW_A, VIEW_B, ta, tb, ridge_response([pa]),
                               ridge_response([pb, spur]))
    assert result.b.max_offset_px < 3.0
    detours = [s for s in result.stretches if s.kind == "detour"]
    assert len(detours) == 1 and detours[0].view == "b"
    assert 15.0 < detours[0].value < 25.0
    assert np.linalg.norm(np.array(detours[0].middle_px) - pb[k]) < 12.0
    assert c3.s_mm[k] - 8.0 < detours[0].start_mm <= c3.s_mm[k] <= detours[0].end_mm
    assert "detours" in detours[0].reason and "waypoint" in detours[0].reason


def test_projection_off_a_thin_vessel_is_caught_by_the_vesselness() -> None:
    """2.5 px off a thin vessel (radius 1 px): inside the 3 px offset, but the
    projection is on the background (response well under 30 % of the trace's)."""
    c3, pa, pb, ta, _ = consistent_case()
    k0, k1 = int(0.4 * len(pb)), int(0.6 * len(pb))
    off = pb.copy()
    t = np.gradient(pb, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    w = np.zeros(len(pb))
    w[k0:k1] = 1.0
    w = ndi.gaussian_filter1d(w, 3.0)
    off = pb + 2.5 * w[:, None] * np.column_stack([-t[:, 1], t[:, 0]])
    tb = trace(off, off[[0, -1]], radius_px=1.0)
    result = check_consistency(c3, VIEW_A, VIEW_B, ta, tb, ridge_response([pa]),
                               ridge_response([off], sigma_px=1.0))
    stretches = [s for s in result.stretches if s.view == "b"]
    assert len(stretches) == 1 and stretches[0].kind == "off_vessel"
    assert "vesselness" in stretches[0].reason
    assert c3.s_mm[k0] - 2 < stretches[0].start_mm < stretches[0].end_mm < c3.s_mm[k1] + 2
    # without the vesselness the offset alone (under 3 px) would not flag it
    plain = check_consistency(c3, VIEW_A, VIEW_B, ta, tb)
    assert plain.ok


@pytest.mark.parametrize("field_name", ["offset_px", "arc_length_pct", "detour_excess_px"])
def test_thresholds_are_reported(field_name: str) -> None:
    c3, pa, pb, ta, tb = consistent_case()
    th = ConsistencyThresholds()
    result = check_consistency(c3, VIEW_A, VIEW_B, ta, tb, thresholds=th)
    assert result.to_dict()["thresholds"][field_name] == getattr(th, field_name)


def _triangulated(ta: Centerline2D, tb: Centerline2D) -> Centerline3D:
    """The pipeline's 3D centerline from two traces (match3 + triangulation + spline)."""
    from recon.correspond.matching import match_centerlines
    from recon.correspond.triangulation import build_centerline_3d

    m = match_centerlines(ta, tb, VIEW_A, VIEW_B, method="match3")
    return build_centerline_3d(m, VIEW_A, VIEW_B)


def test_after_triangulation_a_consistent_pair_passes() -> None:
    _, pa, pb, ta, tb = consistent_case()
    c3 = _triangulated(ta, tb)
    result = check_consistency(c3, VIEW_A, VIEW_B, ta, tb, ridge_response([pa]),
                               ridge_response([pb]))
    assert result.ok, [s.reason for s in result.stretches]
    assert np.abs(result.a.hidden_bend_deg).max() < 20.0
    assert np.abs(result.b.hidden_bend_deg).max() < 20.0


@pytest.mark.parametrize("height_px", [8.0, 14.0])
def test_after_triangulation_a_detour_in_b_is_flagged_at_the_right_place(height_px) -> None:
    """Triangulation absorbs B's detour into A's depth (the projections agree in both
    views): the check finds it as a bend that A does not show, on B, where it is."""
    c_true, pa, pb, ta, _ = consistent_case()
    lo, hi = 0.45, 0.65
    detour = bump(pb, lo, hi, height_px=height_px)
    tb = trace(detour, detour[[0, -1]])
    c3 = _triangulated(ta, tb)
    result = check_consistency(c3, VIEW_A, VIEW_B, ta, tb, ridge_response([pa]),
                               ridge_response([pb, detour]))
    assert not result.ok
    assert all(st.view == "b" for st in result.stretches), [s.reason for s in result.stretches]
    frac = arclength(pb) / arclength(pb)[-1]
    s_lo, s_hi = np.interp([lo, hi], frac, c_true.s_mm)
    # the 3D curve is a little longer than the truth over the detour: allow for it
    slack = c3.length_mm - c_true.length_mm + 2.0
    for st in result.stretches:
        assert st.kind == "depth_bend"
        assert s_lo - slack < st.start_mm < st.end_mm < s_hi + slack
        assert "only view B's trace bends there" in st.reason
        # its 2D place is on the bulge in B
        assert np.min(np.linalg.norm(detour - np.array(st.middle_px), axis=1)) < 3.0


def _straight_pair(direction: np.ndarray, bridged: tuple[float, float]):
    """A straight 40 mm vessel along a world ``direction``, exact traces in both views,
    view A's fits bridged (reliability 0.01) over the arc fractions ``bridged``."""
    s = np.arange(0.0, 40.0, 0.25)
    X = (s - 20.0)[:, None] * direction[None, :]
    tang = np.tile(direction, (len(s), 1))
    m = len(s)
    c3 = Centerline3D(X_world=X, s_mm=s, tangents=tang, radius_a_mm=np.ones(m),
                      radius_b_mm=np.ones(m), X_raw_world=X, points_a_px=VIEW_A.project(X),
                      points_b_px=VIEW_B.project(X))
    pa, pb = VIEW_A.project(X), VIEW_B.project(X)
    ta, tb = trace(pa, pa[[0, -1]]), trace(pb, pb[[0, -1]])
    u = arclength(ta.points_px) / arclength(ta.points_px)[-1]
    rel = np.where((u > bridged[0]) & (u < bridged[1]), 0.01, 1.0)
    ta = Centerline2D(points_px=ta.points_px, radius_px=ta.radius_px,
                      brightness=ta.brightness, clicks_px=ta.clicks_px, reliability=rel)
    return c3, pa, pb, ta, tb


def _angle_to_epipolar_deg(pa: np.ndarray, pb: np.ndarray) -> float:
    """Median angle between the vessel in A and A's epipolar lines (from the
    fundamental matrix, independently of the code under test)."""
    lines = epipolar_lines(pb, VIEW_B, VIEW_A)
    tan = np.gradient(pa, axis=0)
    tan /= np.linalg.norm(tan, axis=1, keepdims=True)
    along = np.column_stack([lines[:, 1], -lines[:, 0]])
    return float(np.median(np.degrees(np.arccos(np.abs(np.sum(tan * along, axis=1))))))


def test_a_bridged_overlap_across_the_epipolar_lines_is_listed_on_its_view() -> None:
    # along world z the vessel crosses A's epipolar lines (~70 deg): a sideways error of
    # A's bridge would move the 3D point along B's ray, which B cannot see
    c3, pa, pb, ta, tb = _straight_pair(np.array([0.0, 0.0, 1.0]), (0.40, 0.55))
    assert _angle_to_epipolar_deg(pa, pb) > 60.0
    result = check_consistency(c3, VIEW_A, VIEW_B, ta, tb, ridge_response([pa]),
                               ridge_response([pb]))
    overlaps = [st for st in result.stretches if st.kind == "overlap"]
    assert [st.view for st in overlaps] == ["a"], [st.reason for st in result.stretches]
    st = overlaps[0]
    assert 0.40 * 40 - 1.0 < st.start_mm and st.end_mm < 0.55 * 40 + 1.0
    assert st.end_mm - st.start_mm > 4.0
    assert st.value == pytest.approx(0.01)
    assert "view B cannot check" in st.reason
    assert result.a.flagged.any() and not result.b.flagged.any()
    assert json.loads(json.dumps(result.to_dict()))["stretches"][0]["kind"] == "overlap"


def test_a_bridged_overlap_along_the_epipolar_lines_is_left_to_the_other_view() -> None:
    # along world x the vessel runs near A's epipolar lines (~20 deg): B sees a sideways
    # error there (as an offset), so the bridge alone is not listed
    c3, pa, pb, ta, tb = _straight_pair(np.array([1.0, 0.0, 0.0]), (0.40, 0.55))
    assert _angle_to_epipolar_deg(pa, pb) < 30.0
    result = check_consistency(c3, VIEW_A, VIEW_B, ta, tb, ridge_response([pa]),
                               ridge_response([pb]))
    assert result.ok, [s.reason for s in result.stretches]


def test_a_single_bridged_fit_is_not_an_overlap() -> None:
    c3, pa, pb, ta, tb = _straight_pair(np.array([0.0, 0.0, 1.0]), (0.500, 0.505))
    result = check_consistency(c3, VIEW_A, VIEW_B, ta, tb, ridge_response([pa]),
                               ridge_response([pb]))
    assert result.ok, [s.reason for s in result.stretches]
