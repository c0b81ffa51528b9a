"""One view's 2D trace from its clicks, with its image's intensity mapping resolved once;
and both views' traces.

The pipeline's tracing step (:func:`recon.pipeline.reconstruct_pair`, step 1) and the
3D tracer's refinement in each view (:mod:`recon.trace3d`) both call these.
"""

from __future__ import annotations

import numpy as np

from recon.trace.centerline import VesselnessMap, trace_segment
from recon.trace.intensity import IntensityMapping, is_display_processed, resolve_mapping
from recon.types import Angiogram, Centerline2D

__all__ = ["trace_pair", "trace_view"]


def trace_pair(
    angios: tuple[Angiogram, Angiogram],
    clicks_px: tuple[np.ndarray, np.ndarray],
    vmaps: tuple[VesselnessMap, VesselnessMap],
    pixel_mm: tuple[float, float],
    intensity: tuple[str, str],
) -> tuple[Centerline2D, Centerline2D]:
    """Both views' traces (A, B), each by :func:`trace_view`."""
    return (trace_view(angios[0], clicks_px[0], vmaps[0], "A", pixel_mm[0], intensity[0]),
            trace_view(angios[1], clicks_px[1], vmaps[1], "B", pixel_mm[1], intensity[1]))


def trace_view(
    angio: Angiogram,
    clicks_px: np.ndarray,
    vmap: VesselnessMap,
    view: str,
    pixel_mm: float,
    intensity: str | IntensityMapping,
) -> Centerline2D:
    """One view's trace, with the intensity mapping resolved once for its image (or given).

    A display-processed file (tag DISP, DRM, ...) with the mapping left to "auto" is
    neither "lin" nor "log": its radius is fitted under the Box-Cox power that the
    trace's own profiles fit best (:func:`recon.trace.centerline.trace_segment` given "auto").
    """
    relationship = angio.info.get("pixel_intensity_relationship")
    fit_power = intensity == "auto" and is_display_processed(relationship)
    mapping = intensity if isinstance(intensity, IntensityMapping) or fit_power else \
        resolve_mapping(angio.image, relationship, intensity, vesselness=vmap)
    return trace_segment(
        angio.image,
        clicks_px,
        vesselness=vmap,
        view=view,
        pixel_mm=pixel_mm,
        relationship=relationship,
        intensity=mapping,
    )
