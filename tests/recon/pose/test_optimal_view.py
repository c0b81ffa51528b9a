"""recon.pose.optimal_view: foreshortening of a segment and the best C-arm angle."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from recon.geometry import ViewGeometry
from recon.pose.optimal_view import foreshortening_pct, optimal_view, overlap_pct

VIEW = ViewGeometry(alpha_deg=0.0, beta_deg=0.0, sid_mm=1000.0, sod_mm=750.0,
                    pixel_spacing_mm=(0.3, 0.3), rows=512, cols=512)


def test_a_segment_across_the_beam_is_not_shortened_and_one_along_it_is() -> None:
    d = VIEW.R_view_from_world  # rows: column axis, row axis, central ray (world)
    s = np.linspace(-20.0, 20.0, 81)[:, None]
    across = s * d[0]
    assert foreshortening_pct(across, VIEW) == pytest.approx(0.0, abs=0.05)
    tilted = s * (np.cos(np.radians(60)) * d[0] + np.sin(np.radians(60)) * d[2])
    # a straight piece at 60 deg to the detector keeps cos 60 = 50 % of its length
    # (to within the ray's spread over the piece)
    assert foreshortening_pct(tilted, VIEW) == pytest.approx(50.0, abs=1.5)


def test_the_best_view_looks_at_the_segment_from_the_side() -> None:
    # A straight 40 mm segment along the world x axis: seen from LAO/RAO 90 it is
    # end-on; at alpha 0, beta 0 its full length shows (within the grid's ray spread).
    X = np.column_stack([np.linspace(-20, 20, 81), np.zeros(81), np.zeros(81)])
    r = np.full(81, 1.5)
    res = optimal_view(X, r, VIEW, {"a": VIEW, "b": replace(VIEW, alpha_deg=60.0)})
    assert res.foreshortening_pct < 1.0 and abs(res.angles_deg[0]) <= 10.0
    assert res.current_foreshortening_pct["b"] == pytest.approx(50.0, abs=1.5)
    i, j = list(res.beta_grid_deg).index(0.0), list(res.alpha_grid_deg).index(90.0)
    assert res.foreshortening_map_pct[i, j] > 95.0  # LAO 90: the segment runs along the ray
    doc = res.to_dict()
    assert set(doc) >= {"angles_deg", "foreshortening_pct", "overlap_pct", "grid"}
    assert np.asarray(doc["grid"]["foreshortening_pct"]).shape == (
        len(res.beta_grid_deg), len(res.alpha_grid_deg))


def test_overlap_of_a_loop_that_crosses_itself_in_projection() -> None:
    t = np.linspace(0, 2 * np.pi * 0.9, 300)
    loop = np.column_stack([15 * np.cos(t), np.zeros_like(t), 15 * np.sin(t)])  # x-z plane
    r = np.full(len(t), 1.5)
    d = VIEW.R_view_from_world
    face_on = VIEW
    # VIEW's central ray runs along -y (alpha 0, beta 0): the loop's plane x-z is seen
    # face on, so nothing overlaps; seen edge-on (alpha 90) it folds onto itself.
    assert abs(d[2][1]) == pytest.approx(1.0)
    assert overlap_pct(loop, r, face_on) == 0.0
    assert overlap_pct(loop, r, replace(VIEW, alpha_deg=90.0)) > 50.0
    other = (np.array([[0.0, 0.0, -30.0], [0.0, 0.0, 30.0]]), np.array([1.0, 1.0]))
    assert overlap_pct(loop, r, VIEW, others=(other,)) > 0.0


def test_the_map_agrees_with_the_views_it_stands_for() -> None:
    t = np.linspace(0, 3, 200)
    X = np.column_stack([30 * np.cos(t), 20 * np.sin(t), 10 * t])  # a helix piece, mm
    r = np.full(len(t), 1.5)
    res = optimal_view(X, r, VIEW)
    for alpha, beta in ((-30.0, 20.0), (45.0, -25.0), (90.0, 0.0)):
        i, j = list(res.beta_grid_deg).index(beta), list(res.alpha_grid_deg).index(alpha)
        view = replace(VIEW, alpha_deg=alpha, beta_deg=beta)
        assert res.foreshortening_map_pct[i, j] == pytest.approx(
            foreshortening_pct(X, view), abs=0.3)
        assert res.overlap_map_pct[i, j] == pytest.approx(overlap_pct(X, r, view), abs=3.0)
