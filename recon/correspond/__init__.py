"""Correspondence between the views and the 3D centreline: the CBOCD descriptor, the
adaptive-step dynamic programming, triangulation, the cross-view consistency check.

The names the pipeline uses are re-exported here and loaded on first use
(so that importing one module of the package does not import the others).
"""

from __future__ import annotations

from recon import lazy_exports

_EXPORTS = {
    "ConsistencyResult": "recon.correspond.consistency",
    "check_consistency": "recon.correspond.consistency",
    "match_centerlines": "recon.correspond.matching",
    "build_centerline_3d": "recon.correspond.triangulation",
    "point_polyline_distance": "recon.correspond.triangulation",
    "table3_metrics": "recon.correspond.triangulation",
}

__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
