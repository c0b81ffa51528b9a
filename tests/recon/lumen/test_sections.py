"""The sections of many centerlines at once (recon.lumen.sections.section_areas)."""

from dataclasses import replace

import numpy as np
import pytest
from support import centerline_3d, straight

from recon.geometry import ViewGeometry
from recon.lumen.sections import section_areas
from recon.lumen.surface import elliptic_cross_sections

VIEW_A = ViewGeometry(-30.0, 0.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)
VIEW_B = ViewGeometry(40.0, 15.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)


def _draws(n: int, m: int = 120) -> tuple[list, list]:
    """n curved centerlines of m points with unequal calipers and fill ratios (the
    densitometric blend on part of them), and n slightly moved views B."""
    rng = np.random.default_rng(3)
    s = np.linspace(0.0, 30.0, m)
    lines, views = [], []
    for k in range(n):
        X = np.stack([s, 4.0 * np.sin(s / 7.0 + k), 2.0 * np.cos(s / 5.0)], axis=1)
        r_a = 1.2 + 0.3 * np.sin(s / 3.0 + k)
        r_b = r_a * (1.0 + 0.4 * rng.uniform(-1.0, 1.0, m))
        cl = centerline_3d(X, r_a, r_b)
        cl = replace(cl, fill_a=rng.uniform(0.7, 1.3, m), fill_b=rng.uniform(0.7, 1.3, m))
        lines.append(cl)
        views.append(VIEW_B.with_correction(rng.normal(0.0, 0.02, 3), rng.normal(0.0, 2.0, 3)))
    return lines, views


def test_each_row_is_the_one_centerline_sections_area_to_the_bit() -> None:
    lines, views = _draws(5)
    # one draw's vessel runs along view B's rays: the fallback line for every point
    along = VIEW_B.source_world + np.linspace(300.0, 330.0, 120)[:, None] * np.array(
        [0.0, 0.6, 0.8])
    lines[2] = replace(centerline_3d(along, 1.0, 1.3), fill_a=lines[2].fill_a,
                       fill_b=lines[2].fill_b)
    views[2] = VIEW_B
    areas = section_areas(lines, VIEW_A, views)
    assert areas.shape == (5, 120)
    for cl, view, row in zip(lines, views, areas, strict=True):
        np.testing.assert_array_equal(row, elliptic_cross_sections(cl, VIEW_A, view).area_mm2)


def test_round_sections_have_the_circle_area() -> None:
    cl = centerline_3d(straight(), 1.5)
    areas = section_areas([cl, cl], VIEW_A, [VIEW_B, VIEW_B])
    np.testing.assert_allclose(areas, np.pi * 1.5**2, rtol=1e-12)


def test_centerlines_of_different_lengths_or_views_are_refused() -> None:
    lines, views = _draws(2)
    with pytest.raises(ValueError, match="one view B per centerline"):
        section_areas(lines, VIEW_A, views[:1])
    short = centerline_3d(straight(length=10.0), 1.0)
    with pytest.raises(ValueError, match="one length"):
        section_areas([lines[0], short], VIEW_A, views)
    with pytest.raises(ValueError, match="None on some"):
        section_areas([lines[0], replace(lines[1], fill_a=None)], VIEW_A, views)
