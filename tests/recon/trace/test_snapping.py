"""Tests of recon.trace.snapping: a click moves across the vessel onto its centre, not along."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from test_intensity import path_length, xray
from test_vesselness import FINE_PIXEL_MM

from recon.trace.centerline import TraceError, compute_vesselness, snap_click, trace_segment


def test_a_click_inside_a_35_px_wide_vessel_snaps_to_its_centre() -> None:
    t = np.linspace(0.0, 1.0, 4000)[:, None]
    axis = np.array([100.0, 300.0]) * (1 - t) + np.array([900.0, 600.0]) * t
    tangent = (axis[-1] - axis[0]) / np.linalg.norm(axis[-1] - axis[0])
    normal = np.array([-tangent[1], tangent[0]])
    img = xray(path_length((1024, 1024), axis, 17.5, ss=2), "lin", mu=0.02)
    vmap = compute_vesselness(img, pixel_mm=FINE_PIXEL_MM)
    for across in (-12.0, -6.0, 0.0, 8.0, 14.0):
        click = axis[2000] + across * normal
        snapped, moved = snap_click(vmap, click)
        assert cKDTree(axis).query(snapped)[0] < 1.5, across
        assert abs((snapped - click) @ tangent) < 1.0  # across, not along
        assert moved == pytest.approx(np.hypot(*(snapped - click)))
    # and the trace of it: centre and radius
    cl = trace_segment(img, [axis[300], axis[2000], axis[-300]], vesselness=vmap)
    assert np.sqrt(np.mean(cKDTree(axis).query(cl.points_px)[0] ** 2)) < 0.3
    assert np.median(cl.radius_px) == pytest.approx(17.5, rel=0.02)


def test_snapping_moves_at_most_about_one_radius_along_a_curved_vessel() -> None:
    a = np.linspace(-2.4, -0.7, 5000)
    curve = np.column_stack([125 + 110 * np.cos(a), 190 + 110 * np.sin(a)])
    radius = 2.5
    img = xray(path_length((200, 250), curve, radius), "lin", mu=0.06)
    vmap = compute_vesselness(img)
    tree = cKDTree(curve)
    rng = np.random.default_rng(4)
    for k in rng.integers(600, 4400, size=25):
        t = np.gradient(curve, axis=0)[k]
        t /= np.linalg.norm(t)
        n = np.array([-t[1], t[0]])
        click = curve[k] + rng.uniform(-6.0, 6.0) * n + rng.uniform(-1.0, 1.0) * t
        snapped, _ = snap_click(vmap, click)
        d, j = tree.query(snapped)
        assert d < 1.0
        # along the vessel: from the click's foot to the snapped point's foot
        along = np.sum(np.linalg.norm(np.diff(curve[min(j, k):max(j, k) + 1], axis=0), axis=1))
        foot = np.abs((click - curve[k]) @ t)
        assert along <= foot + radius, (k, along)


def test_a_click_beyond_a_vessel_end_snaps_within_a_radius_of_the_end() -> None:
    t = np.linspace(0.0, 1.0, 3000)[:, None]
    line = np.array([20.0, 60.0]) * (1 - t) + np.array([120.0, 60.0]) * t
    img = xray(path_length((120, 200), line, 3.0), "lin", mu=0.06)
    vmap = compute_vesselness(img)
    snapped, _ = snap_click(vmap, (123.0, 61.5))
    # the ridge fades over the last radius: the end is found to ~1 radius
    assert abs(snapped[1] - 60.0) < 3.0 and 117.0 <= snapped[0] <= 124.0
    with pytest.raises(TraceError, match="from any vessel"):
        snap_click(vmap, (170.0, 60.0), max_distance_px=8.0)
