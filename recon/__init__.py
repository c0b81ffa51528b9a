"""coronary3d's numerical pipeline: pure arrays and small frozen dataclasses.

The public API is re-exported here and loaded on first use, so that
``import recon`` (and the command line's start-up) stays light.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

_EXPORTS = {
    "ViewGeometry": "recon.geometry",
    "triangulate": "recon.geometry",
    "epipolar_lines": "recon.geometry",
    "fundamental_matrix": "recon.geometry",
    "Seeds": "recon.seeds",
    "load_seeds": "recon.io.seeds_file",
    "save_seeds": "recon.io.seeds_file",
    "Centerline2D": "recon.types",
    "Centerline3D": "recon.types",
    "Matching": "recon.types",
    "Angiogram": "recon.types",
    "load_angiogram": "recon.io.angiogram",
    "LoadError": "recon.errors",
    "compute_vesselness": "recon.centerline",
    "trace_segment": "recon.centerline",
    "calibrate": "recon.calibration",
    "cbocd_descriptor": "recon.cbocd",
    "match_centerlines": "recon.matching",
    "build_centerline_3d": "recon.triangulation",
    "build_surface": "recon.surface",
    "export_mesh": "recon.io.outputs",
    "measure_lumen": "recon.measure",
    "make_phantom": "recon.synth",
    "ReconstructionOptions": "recon.pipeline",
    "reconstruct_pair": "recon.pipeline",
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'recon' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
