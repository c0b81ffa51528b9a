"""The 2D tracing of one view: vessel measures, snapping, the route between clicks, the
sub-pixel centre and radius fits, the guiding catheter.

The names the pipeline uses are re-exported here and loaded on first use
(so that importing one module of the package does not import the others).
"""

from __future__ import annotations

from recon import lazy_exports

_EXPORTS = {
    "VesselnessMap": "recon.trace.centerline",
    "compute_vesselness": "recon.trace.centerline",
    "trace_segment": "recon.trace.centerline",
    "IntensityMapping": "recon.trace.intensity",
    "is_display_processed": "recon.trace.intensity",
    "resolve_mapping": "recon.trace.intensity",
    "TraceError": "recon.trace.trace_error",
    "trace_pair": "recon.trace.pair",
    "trace_view": "recon.trace.pair",
}

__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
