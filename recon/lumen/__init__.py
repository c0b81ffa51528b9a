"""The lumen in 3D: elliptic sections, densitometry, the watertight surface, the QCA
measurements and the bifurcation QCA.

The names the pipeline uses are re-exported here and loaded on first use
(so that importing one module of the package does not import the others).
"""

from __future__ import annotations

from recon import lazy_exports

_EXPORTS = {
    "BifurcationQCA": "recon.lumen.bifurcation",
    "Junction": "recon.lumen.bifurcation",
    "bifurcation_qca": "recon.lumen.bifurcation",
    "carina_s_mm": "recon.lumen.bifurcation",
    "fill_names": "recon.lumen.bifurcation",
    "literal": "recon.lumen.bifurcation",
    "with_fill_ratios": "recon.lumen.densitometry",
    "LumenProfile": "recon.lumen.measure",
    "Measurements": "recon.lumen.measure",
    "lumen_profile": "recon.lumen.measure",
    "measure_lumen": "recon.lumen.measure",
    "SurfaceResult": "recon.lumen.surface",
    "TreeSurface": "recon.lumen.surface",
    "build_surface": "recon.lumen.surface",
    "build_tree_surface": "recon.lumen.surface",
}

__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
