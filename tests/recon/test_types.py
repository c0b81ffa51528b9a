"""Shared pipeline dataclasses (recon/types.py)."""

from __future__ import annotations

import numpy as np
import pytest

from recon.types import Centerline2D


def _line(n: int = 11) -> Centerline2D:
    pts = np.column_stack([np.linspace(0.0, 10.0, n), np.zeros(n)])
    return Centerline2D(pts, np.full(n, 2.0), np.linspace(100.0, 0.0, n))


def test_reliability_defaults_to_ones_and_is_checked() -> None:
    cl = _line()
    assert np.array_equal(cl.reliability, np.ones(11))
    with pytest.raises(ValueError, match="reliability"):
        Centerline2D(cl.points_px, cl.radius_px, cl.brightness, reliability=np.ones(3))


def test_resample_carries_radius_brightness_and_reliability() -> None:
    cl = _line()
    reliability = np.where(np.arange(11) < 5, 1.0, 0.2)
    cl = Centerline2D(cl.points_px, cl.radius_px, cl.brightness, reliability=reliability)
    fine = cl.resample(21)  # every 0.5 units of arc
    assert fine.points_px.shape == (21, 2)
    assert np.allclose(fine.brightness, np.linspace(100.0, 0.0, 21))
    assert np.allclose(fine.reliability[:9], 1.0) and np.allclose(fine.reliability[10:], 0.2)


def test_overlap_stretches_in_mm_of_arc() -> None:
    from recon.types import Centerline3D

    m = 11
    s_mm = np.arange(m, dtype=float)
    X = np.column_stack([s_mm, np.zeros(m), np.zeros(m)])
    overlap_a = np.zeros(m, dtype=bool)
    overlap_a[[2, 3, 4, 8]] = True
    c3 = Centerline3D(X, s_mm, np.tile([1.0, 0, 0], (m, 1)), np.ones(m), np.ones(m),
                      X, X[:, :2], X[:, :2], overlap_a=overlap_a)
    assert c3.overlap_stretches_mm("a") == [[2.0, 4.0], [8.0, 8.0]]
    assert c3.overlap_stretches_mm("b") == []
