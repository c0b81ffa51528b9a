"""The edge of the project: the only package that touches files or pydicom.

Reading angiograms (XA DICOM, or an image file with a geometry JSON),
geometry overrides, frame choice, seeds.json, the output files (centerline
CSV and VTP, report JSON, meshes, DICOM SR), batch runs on Dask, the
phantom's case files and the bundled demo.
Everything else in ``recon`` takes and returns arrays and dataclasses.

Names are re-exported here and loaded on first use, so that importing
``recon.io`` for one small job (the demo's paths) does not load pydicom.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    # files.py: the one JSON reader and the one atomic writer
    "read_json": "recon.io.files",
    "atomic_write_bytes": "recon.io.files",
    # reading angiograms
    "load_angiogram": "recon.io.angiogram",
    "describe_file": "recon.io.describe",
    "format_description": "recon.io.describe",
    "GeometryOverrides": "recon.io.overrides",
    "vessel_contrast_scores": "recon.io.frames",
    "write_xa_dicom": "recon.io.dicom_write",
    # seeds.json
    "load_seeds": "recon.io.seeds_file",
    "save_seeds": "recon.io.seeds_file",
    # outputs
    "MESH_FORMATS": "recon.io.outputs",
    "export_mesh": "recon.io.outputs",
    "centerline_csv": "recon.io.outputs",
    "outputs_as_bytes": "recon.io.outputs",
    "write_outputs": "recon.io.outputs",
    "centerline_vtp": "recon.io.outputs",
    "read_sr_sources": "recon.io.sr",
    "measurement_report_sr": "recon.io.sr",
    # batch runs on Dask
    "read_manifest": "recon.io.manifest",
    "run_case": "recon.io.batch",
    "run_batch": "recon.io.engine",
    # phantom case files
    "write_phantom_case": "recon.io.phantom_case",
    "load_truth": "recon.io.phantom_case",
    # the bundled demo
    "demo_dir": "recon.io.demo",
    "demo_paths": "recon.io.demo",
    # errors
    "LoadError": "recon.errors",
    "OutputError": "recon.errors",
}

__all__ = list(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'recon.io' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
