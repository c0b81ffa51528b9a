"""The 3D tracing step of the pipeline: both views' traces from one 3D path.

Pipeline of :func:`trace_in_3d` (view B already calibrated on the clicks)::

    each view's vessel evidence (recon.trace3d.evidence)
      ->  the 3D path between the end clicks through the waypoints' rays
          (recon.trace3d.path3d)
      ->  each view traced as in 2D (recon.trace.pair) inside a corridor around the
          path's image, from the clicks moved onto that image (recon.trace3d.corridor)
      ->  the stretches left ambiguous: where the path's image in B runs along B's
          epipolar lines.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from recon.geometry import ViewGeometry
from recon.trace.pair import trace_pair
from recon.trace.vesselness import VesselnessMap
from recon.trace3d.corridor import clicks_on_path, corridor_maps
from recon.trace3d.evidence import ViewEvidence, view_evidence
from recon.trace3d.path3d import COARSE_MM, Path3D, trace_path_3d
from recon.types import Angiogram, Centerline2D

__all__ = ["Traced3D", "evidence_pair", "trace_in_3d", "ambiguous_stretches", "path_shift_px"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Traced3D:
    """The 3D tracer's result: both views' traces and the path they came from.

    traced : (A, B) the 2D traces, refined by the 2D fits inside the path's corridor.
    path : the 3D path.
    view_b : B's pose the path was searched under.
    evidence : (A, B) the views' vessel evidence (it depends on the images only: a search
        under another pose of B, or another segment of the same pair, reuses it).
    """

    traced: tuple[Centerline2D, Centerline2D]
    path: Path3D
    view_b: ViewGeometry
    evidence: tuple[ViewEvidence, ViewEvidence]


def evidence_pair(angios: tuple[Angiogram, Angiogram],
                  vmaps: tuple[VesselnessMap, VesselnessMap]) -> tuple[ViewEvidence, ...]:
    """Both views' vessel evidence, with the coarse search's voxel footprint in each view
    (its pixel size at the isocentre is a header value that calibration does not move)."""
    return tuple(view_evidence(angio.image, vmap, COARSE_MM / angio.geometry.pixel_mm_at_isocenter)
                 for angio, vmap in zip(angios, vmaps, strict=True))


def trace_in_3d(
    angios: tuple[Angiogram, Angiogram],
    clicks_px: tuple[FloatArray, FloatArray],
    vmaps: tuple[VesselnessMap, VesselnessMap],
    view_a: ViewGeometry,
    view_b: ViewGeometry,
    intensity: tuple[str, str],
    tol_px: float,
    evidence: tuple[ViewEvidence, ViewEvidence] | None = None,
) -> Traced3D:
    """Both views' traces from the 3D path that both vote on (module docstring).

    ``clicks_px``: each view's clicks (K, 2) as clicked (proximal, waypoints, distal);
    ``view_b``: B calibrated on the clicks; ``tol_px``: its remaining error (px);
    ``evidence``: the views' :func:`evidence_pair` when the caller has it.
    Raises :class:`~recon.trace.trace_error.TraceError` (one line naming the view and
    click) when the ends do not meet in 3D or no path has vessel support in both views.
    """
    pixel_mm = (view_a.pixel_mm_at_isocenter, view_b.pixel_mm_at_isocenter)
    ev_a, ev_b = evidence if evidence is not None else evidence_pair(angios, vmaps)
    path = trace_path_3d(ev_a, ev_b, view_a, view_b, clicks_px[0], clicks_px[1], tol_px)
    maps = corridor_maps(vmaps, path, (view_a, view_b), clicks_px)
    on_path = (clicks_on_path(clicks_px[0], path.projected(view_a)),
               clicks_on_path(clicks_px[1], path.projected(view_b)))
    traced = trace_pair(angios, on_path, maps, pixel_mm, intensity)
    return Traced3D(traced=traced, path=path, view_b=view_b, evidence=(ev_a, ev_b))


def path_shift_px(path: Path3D, view_before: ViewGeometry, view_after: ViewGeometry) -> float:
    """How far (px, the largest over the path) the path's image in B moves between two
    poses of B: when calibration on the traces moves it past the tolerance, trace again."""
    return float(np.max(np.linalg.norm(path.projected(view_after) - path.projected(view_before),
                                       axis=1)))


def ambiguous_stretches(path: Path3D) -> list[dict]:
    """The path's stretches that two views cannot settle, as report entries: each
    ``{"start_mm", "end_mm", "reason"}`` in the path's arc length."""
    out = []
    m = np.concatenate([[False], path.along_epipolar, [False]]).astype(np.int8)
    starts, stops = np.nonzero(np.diff(m) == 1)[0], np.nonzero(np.diff(m) == -1)[0]
    for a, b in zip(starts, stops, strict=True):
        out.append({"start_mm": round(float(path.s_mm[a]), 1),
                    "end_mm": round(float(path.s_mm[b - 1]), 1),
                    "reason": "runs along the epipolar lines: a sideways error in one view "
                              "does not show in the other"})
    return out
