"""The colours of the 3D model: by lumen diameter (the default) or by FFR, and the FFR's
colour key. Pure numpy (no viser): :mod:`viewer_app.scene` and
:mod:`viewer_app.tree_view` paint the mesh with them.

The FFR (:mod:`recon.lumen.ffr`, a model estimate for research, not validated against a
pressure wire here) is known along each vessel's pullback (``FFRResult.s_mm`` /
``ffr``). A point of the 3D centerline takes the pullback's value at its arc length (a
point before a branch's carina, inside its parent's lumen, the pullback's first value);
a vertex of the mesh takes the value of its nearest centerline point, a tree's over all
its branches (each branch's own FFR).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import TYPE_CHECKING

import cv2
import numpy as np
from numpy.typing import NDArray

from recon.io.report_pdf import FFR_CUTOFF

if TYPE_CHECKING:
    from recon.pipeline import Reconstruction

__all__ = [
    "FFR_CUTOFF",
    "FFR_GREY",
    "FFR_KEY_TEXT",
    "centerline_ffr",
    "diameter_colors",
    "ffr_colors",
    "ffr_key_image",
    "segment_diameter_colors",
    "vertex_ffr",
]

FloatArray = NDArray[np.float64]

#: (FFR, RGB) stops of the colour scale at or below the cut-off: orange at 0.80 to dark
#: red at 0.50 and below ...
FFR_LOW_STOPS = ((0.50, (120, 0, 25)), (0.70, (205, 30, 30)), (FFR_CUTOFF, (250, 120, 40)))
#: ... and above it: light blue just above 0.80 to deep blue at 1.00. The step from
#: orange to light blue marks the cut-off on the model.
FFR_HIGH_STOPS = ((FFR_CUTOFF, (100, 180, 240)), (0.90, (55, 125, 220)),
                  (1.00, (30, 60, 175)))  # (lighter under the page's lights: kept saturated)
FFR_GREY = (170, 170, 170)  # no FFR there (not computed for that vessel)
#: What the model's colours say (the title over the model, the key in the panel).
FFR_KEY_TEXT = (f"red / orange = FFR {FFR_CUTOFF:.2f} or below, blue = above (key under "
                "Reconstruct)")


def diameter_colors(d_mm: FloatArray, ref_mm: float | FloatArray) -> NDArray[np.uint8]:
    """RGB (N, 3) for lumen diameters (N,) against their reference diameters (a scalar
    or (N,), the tapering healthy reference at each point): red at or below half the
    reference, yellow at 75 %, green at the reference and above (the usual QCA colour
    scale)."""
    ref = np.maximum(np.asarray(ref_mm, float), 1e-6)
    r = np.clip(np.asarray(d_mm, float) / ref, 0.5, 1.0)
    stops = np.array([0.5, 0.75, 1.0])
    rgb = np.stack([np.interp(r, stops, [220, 240, 40]), np.interp(r, stops, [30, 200, 180]),
                    np.interp(r, stops, [30, 40, 70])], axis=1)
    return rgb.round().astype(np.uint8)


def _nearest(X_world: FloatArray, vertices_world: FloatArray) -> NDArray[np.int64]:
    """Index (V,) of the point of ``X_world`` (N, 3) nearest each vertex (V, 3)."""
    from scipy.spatial import cKDTree

    _, nearest = cKDTree(np.asarray(X_world, float)).query(np.asarray(vertices_world, float))
    return np.asarray(nearest, dtype=np.int64)


def segment_diameter_colors(rec: Reconstruction, vertices_world: FloatArray
                            ) -> NDArray[np.uint8]:
    """RGB (V, 3) of a segment's mesh vertices (V, 3) (mm, world): the smoothed lumen
    diameter at the nearest 3D centerline point against the local (tapering) reference
    there (:func:`diameter_colors`: a healthy distal vessel stays green)."""
    s = np.asarray(rec.centerline_3d.s_mm, dtype=float)
    prof = rec.profile
    d_mm = np.interp(s, prof.s_mm, prof.diameter_smooth_mm)
    ref_all = np.asarray(prof.reference_diameter_mm, float)
    ref_mm = np.interp(s, prof.s_mm, np.where(np.isfinite(ref_all), ref_all,
                                              float(np.nanmax(ref_all))))
    nearest = _nearest(rec.centerline_3d.X_world, vertices_world)
    return diameter_colors(d_mm[nearest], ref_mm[nearest])


def ffr_colors(ffr: FloatArray) -> NDArray[np.uint8]:
    """RGB (N, 3) for FFR values (N,): :data:`FFR_LOW_STOPS` at or below the cut-off,
    :data:`FFR_HIGH_STOPS` above it, :data:`FFR_GREY` where the value is NaN."""
    v = np.asarray(ffr, dtype=float)
    out = np.empty((len(v), 3))
    for stops, pick in ((FFR_LOW_STOPS, v <= FFR_CUTOFF), (FFR_HIGH_STOPS, v > FFR_CUTOFF)):
        at = np.array([x for x, _ in stops])
        rgb = np.array([c for _, c in stops], float)
        for k in range(3):
            out[pick, k] = np.interp(v[pick], at, rgb[:, k])
    out[~np.isfinite(v)] = FFR_GREY
    return out.round().astype(np.uint8)


def centerline_ffr(rec: Reconstruction) -> FloatArray | None:
    """The FFR (N,) at each point of ``rec``'s 3D centerline (its pullback at the point's
    arc length, held at the pullback's ends), or None when its FFR was not computed."""
    ffr = getattr(rec, "ffr", None)
    if ffr is None:
        return None
    return np.interp(np.asarray(rec.centerline_3d.s_mm, float), np.asarray(ffr.s_mm, float),
                     np.asarray(ffr.ffr, float))


def vertex_ffr(parts: Sequence[Reconstruction], vertices_world: FloatArray) -> FloatArray:
    """The FFR (V,) at each mesh vertex (V, 3) (mm, world): that of the nearest 3D
    centerline point over every part (a tree's branches, or the one segment), each
    part's own pullback; NaN near a part without FFR."""
    values = [centerline_ffr(p) for p in parts]
    X_all = np.vstack([np.asarray(p.centerline_3d.X_world, float) for p in parts])
    v_all = np.concatenate([np.full(len(p.centerline_3d.X_world), np.nan) if v is None else v
                            for p, v in zip(parts, values, strict=True)])
    return v_all[_nearest(X_all, vertices_world)]


@lru_cache(maxsize=2)
def ffr_key_image(width: int = 360, height: int = 112) -> NDArray[np.uint8]:
    """The FFR colour key as an RGB image (H, W, 3): the scale from 0.50 to 1.00 with
    ticks, the cut-off marked, and what the colours are (a model estimate for research).
    Narrow, so that the page's panel shows its text large enough."""
    img = np.full((height, width, 3), 255, np.uint8)
    font, ink = cv2.FONT_HERSHEY_SIMPLEX, (40, 40, 40)
    left, right, top, bar_h = 22, 22, 27, 18  # (under the text: room for the page's button)
    cv2.putText(img, "FFR colours (model estimate, research use)", (4, 15), font, 0.48, ink,
                1, cv2.LINE_AA)
    x = np.arange(left, width - right)
    values = 0.5 + (x - left) / (width - right - 1 - left) * 0.5
    img[top:top + bar_h, left:width - right] = ffr_colors(values)[None, :, :]
    cv2.rectangle(img, (left, top), (width - right - 1, top + bar_h), (90, 90, 90), 1)
    for tick in np.arange(0.5, 1.0 + 1e-9, 0.1):
        tx = int(round(left + (tick - 0.5) / 0.5 * (width - right - 1 - left)))
        cut = abs(tick - FFR_CUTOFF) < 1e-9
        cv2.line(img, (tx, top + bar_h), (tx, top + bar_h + 5), ink, 2 if cut else 1)
        label = f"{tick:.1f}" if not cut else f"{tick:.2f}"
        w = cv2.getTextSize(label, font, 0.48, 1)[0][0]
        cv2.putText(img, label, (tx - w // 2, top + bar_h + 21), font, 0.48, ink,
                    2 if cut else 1, cv2.LINE_AA)
        if cut:  # the cut-off through the bar
            cv2.line(img, (tx, top - 3), (tx, top + bar_h + 3), (0, 0, 0), 2)
    cv2.putText(img, f"red / orange: {FFR_CUTOFF:.2f} or below", (4, height - 26), font, 0.48,
                ink, 1, cv2.LINE_AA)
    cv2.putText(img, "blue: above; grey: no FFR there", (4, height - 8), font, 0.48, ink, 1,
                cv2.LINE_AA)
    img.setflags(write=False)  # cached: one image for every caller
    return img
