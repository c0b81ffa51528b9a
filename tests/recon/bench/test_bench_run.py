"""Every bench's run takes run(cases=None, seed=0); centerline and reconstruct also a suite."""

from __future__ import annotations

import importlib
import inspect
from types import SimpleNamespace

import numpy as np
import pytest
from support import centerline_3d, straight

from recon.bench.common import pose_error
from recon.bench.reconstruct import closed_truth_volume_mm3, section_volume_mm3
from recon.geometry import ViewGeometry
from recon.lumen.surface import build_surface
from recon.synth import make_phantom

BENCHES = ("centerline", "calibration", "matching", "reconstruct", "speed", "intervals",
           "sections", "optimal_view", "calibration_modes")


#: Parameters after (cases, seed): the suite for the benches that take --suite varied,
#: and the click jitter, the Dask workers and the tracer of bench reconstruct.
EXTRA = {"centerline": {"suite": "regular"},
         "reconstruct": {"suite": "regular", "jitter": 0, "workers": None, "tracer": "2d"},
         "intervals": {"workers": None, "checkpoint": None},
         "calibration_modes": {"suite": "regular", "workers": None}}


@pytest.mark.parametrize("name", BENCHES)
def test_run_signature_is_cases_and_seed(name: str) -> None:
    module = importlib.import_module(f"recon.bench.{name}")
    params = inspect.signature(module.run).parameters
    extra = EXTRA.get(name, {})
    assert list(params) == ["cases", "seed", *extra]
    assert params["cases"].default is None and params["seed"].default == 0
    assert {k: params[k].default for k in extra} == extra
    assert all(p.kind is inspect.Parameter.POSITIONAL_OR_KEYWORD for p in params.values())


def test_pose_error_of_the_header_and_of_the_truth() -> None:
    case = make_phantom("data1", 2, render=False)
    X = case.truth.segment_X_world
    assert pose_error(case.view_b_true, case.view_b_true, X) == pytest.approx((0.0, 0.0), abs=1e-9)
    rot_deg, disp_mm = pose_error(case.view_b_nominal, case.view_b_true, X)
    angle = np.degrees(np.linalg.norm(case.truth.correction_rotvec))
    assert rot_deg == pytest.approx(angle, rel=1e-9)
    # The header's rig error moves a point X fixed to the true rig to R^T (X - t).
    R, t = case.view_b_true.R_corr, np.asarray(case.view_b_true.t_corr_mm)
    moved = (X - t) @ R
    assert disp_mm == pytest.approx(np.mean(np.linalg.norm(moved - X, axis=1)), rel=1e-9)
    assert disp_mm > 1.0


def test_the_mesh_volume_is_judged_against_the_truth_closed_the_same_way() -> None:
    """The mesh of a known straight tube carries a cap on each end: the bench's closed
    true volume matches it, and the sections' volume matches the tube without caps."""
    r, length = 1.5, 40.0
    cl = centerline_3d(straight(length=length), r)
    view_a = ViewGeometry(-30.0, 0.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)
    view_b = ViewGeometry(30.0, 0.0, 1000.0, 750.0, (0.39, 0.39), 512, 512)
    surface = build_surface(cl, view_a, view_b)
    rec = SimpleNamespace(surface=surface, centerline_3d=cl)
    radius = np.full(len(cl.s_mm), r)
    truth = SimpleNamespace(segment_radius_mm=radius,
                            segment_volume_mm3=float(np.pi * np.trapezoid(radius**2, cl.s_mm)))
    assert surface.mesh.volume == pytest.approx(closed_truth_volume_mm3(truth), rel=0.01)
    assert section_volume_mm3(rec) == pytest.approx(np.pi * r**2 * length, rel=1e-3)
    # the caps are 5 % of this tube: the open truth would read the mesh 5 % high
    assert surface.mesh.volume / truth.segment_volume_mm3 > 1.04
