"""The 3D tracing: the vessel's centreline as a 3D path that both views vote on; its
images in A and B fix each view's 2D trace (which vessel, which way round a loop).

The names the pipeline uses are re-exported here and loaded on first use.
"""

from __future__ import annotations

from recon import lazy_exports

_EXPORTS = {
    "ViewEvidence": "recon.trace3d.evidence",
    "view_evidence": "recon.trace3d.evidence",
    "Path3D": "recon.trace3d.path3d",
    "trace_path_3d": "recon.trace3d.path3d",
    "corridor_maps": "recon.trace3d.corridor",
    "snap_ends": "recon.trace3d.corridor",
    "clicks_on_path": "recon.trace3d.corridor",
    "CORRIDOR_MIN_PX": "recon.trace3d.corridor",
    "Traced3D": "recon.trace3d.stage",
    "trace_in_3d": "recon.trace3d.stage",
    "evidence_pair": "recon.trace3d.stage",
    "ambiguous_stretches": "recon.trace3d.stage",
    "path_shift_px": "recon.trace3d.stage",
}

__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
