"""The diameter profile chart of the results panel, drawn with cv2 into an RGB array."""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from recon.pipeline import Reconstruction

__all__ = ["profile_plot"]


def profile_plot(rec: Reconstruction, width: int = 640, height: int = 360,
                 lesion: dict[str, float] | None = None) -> NDArray[np.uint8]:
    """Diameter along the vessel as an RGB image (H, W, 3): measured, reference, MLD, lesion.

    ``lesion``: MLD and lesion ends the clinician set (keys ``mld_mm``, ``mld_s_mm``,
    ``lesion_start_s_mm``, ``lesion_end_s_mm``, and optionally ``proximal_reference_mm``
    / ``distal_reference_mm`` for the straight reference between the ends); None: the
    automatic analysis.
    """
    prof = rec.profile
    s = np.asarray(prof.s_mm, dtype=float)
    d = np.asarray(prof.diameter_mm, dtype=float)
    ref = np.asarray(prof.reference_diameter_mm, dtype=float)
    meas = rec.measurements.to_dict()
    if lesion is not None:
        meas = {**meas, **lesion}
    img = np.full((height, width, 3), 255, np.uint8)
    left, right, top, bottom = 56, 14, 26, 40
    x0, x1 = float(s.min()), float(max(s.max(), s.min() + 1e-6))
    ymax = float(np.nanmax(np.concatenate([d, ref]))) * 1.15 or 1.0

    def px(sv: NDArray, dv: NDArray) -> NDArray[np.int32]:
        xs = left + (np.asarray(sv) - x0) / (x1 - x0) * (width - left - right)
        ys = height - bottom - np.asarray(dv) / ymax * (height - top - bottom)
        return np.stack([xs, ys], axis=-1).round().astype(np.int32)

    font = cv2.FONT_HERSHEY_SIMPLEX
    for (lo, hi), colour, label in _flagged_stretches(rec):  # behind everything else
        a, b = px(np.array([lo, hi]), np.zeros(2))
        cv2.rectangle(img, (int(a[0]), top), (max(int(b[0]), int(a[0]) + 1), height - bottom),
                      colour, -1)
        cv2.putText(img, label, (int(a[0]) + 2, top + 12), font, 0.35, (90, 90, 90), 1,
                    cv2.LINE_AA)
    lesion = (meas.get("lesion_start_s_mm"), meas.get("lesion_end_s_mm"))
    if all(v is not None for v in lesion):
        a, b = px(np.array(lesion, float), np.zeros(2))
        cv2.rectangle(img, (int(a[0]), top), (int(b[0]), height - bottom), (255, 225, 225), -1)
        for p in (a, b):
            cv2.line(img, (int(p[0]), top), (int(p[0]), height - bottom), (220, 60, 60), 1)
    cv2.rectangle(img, (left, top), (width - right, height - bottom), (120, 120, 120), 1)
    for k in range(6):  # axis ticks
        yv = ymax * k / 5
        y = int(px(np.array([x0]), np.array([yv]))[0, 1])
        cv2.putText(img, f"{yv:.1f}", (4, y + 4), font, 0.4, (60, 60, 60), 1, cv2.LINE_AA)
        xv = x0 + (x1 - x0) * k / 5
        x = int(px(np.array([xv]), np.array([0.0]))[0, 0])
        cv2.putText(img, f"{xv:.0f}", (x - 8, height - bottom + 16), font, 0.4, (60, 60, 60),
                    1, cv2.LINE_AA)
    cv2.polylines(img, [px(s, ref)], False, (150, 150, 150), 1, cv2.LINE_AA)
    if lesion is not None and "proximal_reference_mm" in lesion:
        ends = np.array([lesion["lesion_start_s_mm"], lesion["lesion_end_s_mm"]])
        refs = np.array([lesion["proximal_reference_mm"], lesion["distal_reference_mm"]])
        cv2.polylines(img, [px(ends, refs)], False, (90, 90, 90), 2, cv2.LINE_AA)
    smooth = getattr(prof, "diameter_smooth_mm", None)
    if smooth is not None:
        cv2.polylines(img, [px(s, d)], False, (160, 190, 235), 1, cv2.LINE_AA)
        d = np.asarray(smooth, dtype=float)
    cv2.polylines(img, [px(s, d)], False, (30, 90, 200), 2, cv2.LINE_AA)
    mld_s = meas.get("mld_s_mm")
    mld = meas.get("mld_mm")
    if mld_s is not None and mld is not None:
        p = px(np.array([mld_s]), np.array([mld]))[0]
        cv2.circle(img, (int(p[0]), int(p[1])), 5, (220, 30, 30), -1, cv2.LINE_AA)
        cv2.putText(img, f"MLD {float(mld):.2f} mm", (int(p[0]) + 7, int(p[1]) + 14), font,
                    0.45, (220, 30, 30), 1, cv2.LINE_AA)
    cv2.putText(img, "diameter (mm) vs arc length (mm); grey: reference; red band: lesion",
                (left, 16), font, 0.4, (40, 40, 40), 1, cv2.LINE_AA)
    return img


BRANCH_BAND = (222, 222, 222)  # a side branch's ostium widens the silhouette
OVERLAP_BAND = (255, 243, 190)  # one view overlapped: the other view's width is used


def _flagged_stretches(rec: Reconstruction) -> list[tuple[tuple[float, float],
                                                          tuple[int, int, int], str]]:
    """The stretches the chart shades, ((start, end) mm, colour, label): side-branch ostia
    (:func:`viewer_app.results.branch_stretches`) and overlapped stretches of either view
    (``Centerline3D.overlap_stretches_mm``). The measured curve is drawn over them."""
    from viewer_app.results import branch_stretches

    out = []
    c = getattr(rec, "centerline_3d", None)
    if c is not None:
        for view in ("a", "b"):
            out += [((lo, hi), OVERLAP_BAND, f"{view.upper()} overlapped")
                    for lo, hi in c.overlap_stretches_mm(view)]
    if c is not None and getattr(rec, "seeds", None) is not None:
        out += [((b["start_mm"], b["end_mm"]), BRANCH_BAND, "branch")
                for b in branch_stretches(rec)]
    return out
