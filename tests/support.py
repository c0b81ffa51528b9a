"""Small known cases shared by several test modules (on the test path via pyproject)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from recon.types import Centerline3D

DATA = Path(__file__).resolve().parent / "data"  # real DICOMs (ORIGIN.md)
DEMO = Path(__file__).resolve().parents[1] / "assets" / "demo"  # the bundled demo pair


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "CORONARY3D_DEBUG"}
    return subprocess.run(
        [sys.executable, "-m", "recon.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=cwd,
        env=env,
    )


def assert_one_line_error(proc: subprocess.CompletedProcess, *fragments: str) -> None:
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.startswith("coronary3d: error:")]
    assert len(lines) == 1, proc.stderr  # one error line (progress lines may precede it)
    for fragment in fragments:
        assert fragment in lines[0]


#: A seeds.json document of version 1 with one segment and one feature.
EXAMPLE_SEEDS = {
    "version": 1,
    "segments": [
        {
            "name": "LAD mid",
            "a": [[170.5, 54.1], [179.9, 139.1], [323.0, 261.2]],
            "b": [[368.6, 101.1], [371.2, 177.0], [401.9, 331.4]],
        }
    ],
    "features": [{"name": "D1 bifurcation", "a": [192.1, 160.3], "b": [379.0, 196.7]}],
}


def centerline_3d(X, r_a, r_b=None) -> Centerline3D:
    """A Centerline3D through the points X (N, 3) mm with radii r_a (and r_b) mm."""
    X = np.asarray(X, dtype=float)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(X, axis=0), axis=1))])
    t = np.gradient(X, s, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    r_a = np.broadcast_to(np.asarray(r_a, dtype=float), (len(X),)).copy()
    r_b = r_a.copy() if r_b is None else np.broadcast_to(r_b, (len(X),)).astype(float)
    return Centerline3D(
        X_world=X,
        s_mm=s,
        tangents=t,
        radius_a_mm=r_a,
        radius_b_mm=r_b,
        X_raw_world=X,
        points_a_px=np.zeros((len(X), 2)),
        points_b_px=np.zeros((len(X), 2)),
    )


def straight(length=40.0, direction=(0.6, 0.0, 0.8), origin=(0.0, 3.0, 0.0), step=0.25):
    """Points (N, 3) mm every ``step`` along a straight line centred on ``origin``."""
    t = np.arange(0.0, length + 1e-9, step) - length / 2
    return np.asarray(origin) + t[:, None] * np.asarray(direction) / np.linalg.norm(direction)
