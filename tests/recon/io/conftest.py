"""Small synthetic XA runs for the recon.io tests."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from recon.geometry import ViewGeometry


def _geometry(rows: int = 80, cols: int = 64) -> ViewGeometry:
    return ViewGeometry(
        alpha_deg=-29.3,
        beta_deg=25.5,
        sid_mm=976.0,
        sod_mm=720.0,
        pixel_spacing_mm=(0.390625, 0.390625),
        rows=rows,
        cols=cols,
    )


def _run_with_line(depths: list[float], rows: int = 80, cols: int = 64) -> np.ndarray:
    """(F, rows, cols) uint16 frames: flat 2000 background, a dark vertical line per frame."""
    frames = np.full((len(depths), rows, cols), 2000, dtype=np.uint16)
    for k, depth in enumerate(depths):
        frames[k, 5:-5, cols // 2 - 1 : cols // 2 + 1] = int(2000 - depth)
    return frames


@pytest.fixture
def xa_geometry() -> Callable[..., ViewGeometry]:
    """``xa_geometry(rows=80, cols=64)``: the IM7 view's geometry for a small image."""
    return _geometry


@pytest.fixture
def run_with_line() -> Callable[..., np.ndarray]:
    """``run_with_line(depths, rows=80, cols=64)``: frames with a dark line of each depth."""
    return _run_with_line
