"""The diameter profile chart of the results panel, drawn with cv2 into an RGB array."""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

if TYPE_CHECKING:
    from recon.pipeline import Reconstruction

__all__ = ["ffr_plot", "profile_plot"]


def _nice_step(span: float, target: int) -> float:
    """A tick step of 1, 2 or 5 x 10^k giving about ``target`` ticks over ``span``."""
    raw = max(span, 1e-9) / target
    k = 10.0 ** np.floor(np.log10(raw))
    return float(k * min((m for m in (1.0, 2.0, 5.0, 10.0) if m * k >= raw), default=10.0))


def profile_plot(rec: Reconstruction, width: int = 640, height: int = 360,
                 lesion: dict[str, float] | None = None) -> NDArray[np.uint8]:
    """Diameter along the vessel as an RGB image (H, W, 3): measured, reference, MLD,
    lesion, the reference sites and the shaded stretches; below it, when the profile has
    ``area_smooth_mm2``, the lumen area on the same arc length.

    ``lesion``: MLD and lesion ends the clinician set (keys ``mld_mm``, ``mld_s_mm``,
    ``lesion_start_s_mm``, ``lesion_end_s_mm``, and optionally ``proximal_reference_mm``
    / ``distal_reference_mm`` at ``proximal_reference_s_mm`` / ``distal_reference_s_mm``
    for the straight reference between the sites); None: the automatic analysis.
    """
    prof = rec.profile
    s = np.asarray(prof.s_mm, dtype=float)
    d = np.asarray(prof.diameter_mm, dtype=float)
    ref = np.asarray(prof.reference_diameter_mm, dtype=float)
    area = getattr(prof, "area_smooth_mm2", None)
    meas = rec.measurements.to_dict()
    if lesion is not None:
        meas = {**meas, **lesion}
    img = np.full((height, width, 3), 255, np.uint8)
    left, right, top = 56, 14, 26
    bottom = 40 if area is None else int(0.34 * height) + 30  # room for the area chart
    x0, x1 = float(s.min()), float(max(s.max(), s.min() + 1e-6))
    ymax = float(np.nanmax(np.concatenate([d, ref]))) * 1.15 or 1.0

    def px(sv: NDArray, dv: NDArray) -> NDArray[np.int32]:
        xs = left + (np.asarray(sv) - x0) / (x1 - x0) * (width - left - right)
        ys = height - bottom - np.asarray(dv) / ymax * (height - top - bottom)
        return np.stack([xs, ys], axis=-1).round().astype(np.int32)

    font, grey = cv2.FONT_HERSHEY_SIMPLEX, (60, 60, 60)
    bands = _flagged_stretches(rec)
    for (lo, hi), colour, _ in bands:  # behind everything else
        a, b = px(np.array([lo, hi]), np.zeros(2))
        cv2.rectangle(img, (int(a[0]), top), (max(int(b[0]), int(a[0]) + 1), height - bottom),
                      colour, -1)
    ends = (meas.get("lesion_start_s_mm"), meas.get("lesion_end_s_mm"))
    if all(v is not None for v in ends):
        a, b = px(np.array(ends, float), np.zeros(2))
        cv2.rectangle(img, (int(a[0]), top), (int(b[0]), height - bottom), (255, 225, 225), -1)
        for p in (a, b):
            cv2.line(img, (int(p[0]), top), (int(p[0]), height - bottom), (220, 60, 60), 1)
    titles: list[tuple[int, int, int]] = []  # (x0, x1, row) of the band titles written
    for (lo, _), _, label in bands:
        x = int(px(np.array([lo]), np.zeros(1))[0, 0]) + 2
        w = cv2.getTextSize(label, font, 0.38, 1)[0][0]
        row = 0  # the first row where it clears the titles before it (bands side by side)
        while any(r == row and x < x1 + 4 and x0 < x + w + 4 for x0, x1, r in titles):
            row += 1
        titles.append((x, x + w, row))
        cv2.putText(img, label, (x, top + 12 + 12 * row), font, 0.38, (90, 90, 90), 1,
                    cv2.LINE_AA)
    cv2.rectangle(img, (left, top), (width - right, height - bottom), (120, 120, 120), 1)
    y_step = _nice_step(ymax, 5)
    for yv in np.arange(0.0, ymax + 1e-9, y_step):  # axis ticks at round values
        y = int(px(np.array([x0]), np.array([yv]))[0, 1])
        cv2.line(img, (left, y), (width - right, y), (235, 235, 235), 1)
        cv2.putText(img, f"{yv:g}", (left - 30, y + 5), font, 0.5, grey, 1, cv2.LINE_AA)
    x_step = _nice_step(x1 - x0, 6)
    for xv in np.arange(np.ceil(x0 / x_step) * x_step, x1 + 1e-9, x_step):
        x = int(px(np.array([xv]), np.array([0.0]))[0, 0])
        cv2.putText(img, f"{xv:g}", (x - 8, height - bottom + 17), font, 0.5, grey, 1,
                    cv2.LINE_AA)
    cv2.polylines(img, [px(s, ref)], False, (150, 150, 150), 1, cv2.LINE_AA)
    sites = (meas.get("proximal_reference_s_mm"), meas.get("distal_reference_s_mm"))
    if lesion is not None and "proximal_reference_mm" in lesion:
        at = np.array([v if v is not None else e for v, e in zip(sites, ends, strict=True)])
        refs = np.array([lesion["proximal_reference_mm"], lesion["distal_reference_mm"]])
        cv2.polylines(img, [px(at, refs)], False, (90, 90, 90), 2, cv2.LINE_AA)
        for p in px(at, refs):  # the reference sites the clinician can move
            for y in range(top, height - bottom, 8):
                cv2.line(img, (int(p[0]), y), (int(p[0]), min(y + 4, height - bottom)),
                         (90, 90, 90), 1)
            cv2.circle(img, (int(p[0]), int(p[1])), 4, (90, 90, 90), -1, cv2.LINE_AA)
    smooth = getattr(prof, "diameter_smooth_mm", None)
    if smooth is not None:
        cv2.polylines(img, [px(s, d)], False, (160, 190, 235), 1, cv2.LINE_AA)
        d = np.asarray(smooth, dtype=float)
    cv2.polylines(img, [px(s, d)], False, (30, 90, 200), 2, cv2.LINE_AA)
    mld_s, mld = meas.get("mld_s_mm"), meas.get("mld_mm")
    if mld_s is not None and mld is not None:
        p = px(np.array([mld_s]), np.array([mld]))[0]
        cv2.circle(img, (int(p[0]), int(p[1])), 5, (220, 30, 30), -1, cv2.LINE_AA)
        cv2.putText(img, f"MLD {float(mld):.2f} mm", (int(p[0]) + 7, int(p[1]) + 14), font,
                    0.5, (220, 30, 30), 1, cv2.LINE_AA)
    title = "diameter (mm); grey: reference, red band: lesion"
    title += ", dashed: reference sites" if lesion is not None else ""
    cv2.putText(img, title, (4, 16), font, 0.46, (40, 40, 40), 1, cv2.LINE_AA)
    if area is not None:
        _area_chart(img, s, np.asarray(area, dtype=float), (left, right, height - bottom + 26),
                    px)
    return img


def _area_chart(img: NDArray[np.uint8], s: FloatArray, area: FloatArray,
                box: tuple[int, int, int], px) -> None:
    """The lumen area (mm², (M,)) under the diameter chart, on the same arc length;
    ``box`` = (left, right, top) px, ``px`` the diameter chart's mapping (for x)."""
    height, width = img.shape[:2]
    left, right, top = box
    bottom = height - 22
    amax = float(np.nanmax(area)) * 1.15 or 1.0
    xs = px(s, np.zeros_like(s))[:, 0]
    ys = (bottom - area / amax * (bottom - top)).round().astype(np.int32)
    cv2.rectangle(img, (left, top), (width - right, bottom), (120, 120, 120), 1)
    font = cv2.FONT_HERSHEY_SIMPLEX
    step = _nice_step(amax, 3)
    for av in np.arange(0.0, amax + 1e-9, step):
        y = int(round(bottom - av / amax * (bottom - top)))
        cv2.line(img, (left, y), (width - right, y), (235, 235, 235), 1)
        cv2.putText(img, f"{av:g}", (left - 30, y + 5), font, 0.45, (60, 60, 60), 1,
                    cv2.LINE_AA)
    cv2.polylines(img, [np.stack([xs, ys], axis=-1)], False, (20, 140, 120), 2, cv2.LINE_AA)
    cv2.putText(img, "area (mm2) vs arc length (mm)", (left, height - 6), font, 0.42,
                (40, 40, 40), 1, cv2.LINE_AA)


BRANCH_BAND = (222, 222, 222)  # a side branch's ostium widens the silhouette
OVERLAP_BAND = (255, 243, 190)  # one view overlapped: the other view's width is used
BORDERLINE_BAND = (255, 236, 214)  # a narrowing below the lesion floor, its interval reaching it


def _flagged_stretches(rec: Reconstruction) -> list[tuple[tuple[float, float],
                                                          tuple[int, int, int], str]]:
    """The stretches the chart shades, ((start, end) mm, colour, label): side-branch ostia
    (:func:`viewer_app.results.branch_stretches`), overlapped stretches of either view
    (``Centerline3D.overlap_stretches_mm``) and borderline narrowings (below the lesion
    floor, their 95 % interval reaching it: ``LesionReport.borderline``). The measured
    curve is drawn over them."""
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
    for b in tuple(getattr(getattr(rec, "lesions", None), "borderline", ()) or ()):
        n = b.narrowing
        out.append(((n.start_s_mm, n.end_s_mm), BORDERLINE_BAND,
                    f"borderline {n.diameter_stenosis_pct:.0f} %"))
    return out


FFR_CURVE = (20, 40, 130)  # the FFR pullback (navy)
FFR_INTERVAL = (200, 216, 248)  # its 95 % interval, shaded
FFR_BAND = (230, 120, 0)  # the flow assumption's two pullbacks, dashed
FFR_CUT = (200, 20, 60)  # the 0.80 cut-off
FFR_LESION = (255, 232, 232)  # a lesion's stretch, numbered


def _dashed(img: NDArray[np.uint8], pts: NDArray[np.int32], colour: tuple[int, int, int],
            dash_px: float = 7.0, gap_px: float = 5.0) -> None:
    """A dashed polyline through ``pts`` (N, 2) px: dashes of ``dash_px`` every
    ``dash_px + gap_px`` along its length."""
    p = np.asarray(pts, float)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    for start in np.arange(0.0, s[-1], dash_px + gap_px):
        at = np.linspace(start, min(start + dash_px, s[-1]), 6)
        seg = np.column_stack([np.interp(at, s, p[:, 0]), np.interp(at, s, p[:, 1])])
        cv2.polylines(img, [seg.round().astype(np.int32)], False, colour, 2, cv2.LINE_AA)


def ffr_plot(rec: Reconstruction, width: int = 440, height: int = 346) -> NDArray[np.uint8]:
    """The FFR pullback as an RGB image (H, W, 3), on the diameter chart's arc length (the
    same margins, so the two line up): the FFR along the vessel (a model estimate for
    research, recon.lumen.ffr), its 95 % interval shaded, the pullbacks at the two
    velocities of the flow assumption dashed (not a confidence interval), a line at the
    0.80 cut-off, the lesions' stretches numbered, the distal value; a legend below.
    ``rec.ffr`` must not be None."""
    from recon.io.report_pdf import FFR_CUTOFF

    ffr = rec.ffr
    s = np.asarray(ffr.s_mm, float)
    values = np.asarray(ffr.ffr, float)
    band = np.asarray(ffr.band, float).reshape(-1, len(s)) if np.size(ffr.band) else \
        np.zeros((0, len(s)))
    has_ci = ffr.ffr_lo is not None and ffr.ffr_hi is not None
    img = np.full((height, width, 3), 255, np.uint8)
    font, ink, grey = cv2.FONT_HERSHEY_SIMPLEX, (40, 40, 40), (60, 60, 60)
    # (bottom: the legend, and room under it for the page's full-screen button)
    left, right, top, bottom = 56, 14, 34, 114
    s_all = np.asarray(rec.profile.s_mm, float)
    x0, x1 = float(min(s_all.min(), s.min())), float(max(s_all.max(), s.max()))
    x1 = max(x1, x0 + 1e-6)
    shown = [values, *band] + ([np.asarray(ffr.ffr_lo, float)] if has_ci else [])
    lowest = float(min(np.nanmin(v) for v in shown))
    y0 = max(0.0, np.floor(min(0.7, lowest - 0.03) * 20.0) / 20.0)
    y1 = 1.02

    def px(sv: NDArray, fv: NDArray) -> NDArray[np.int32]:
        xs = left + (np.asarray(sv, float) - x0) / (x1 - x0) * (width - left - right)
        ys = height - bottom - (np.asarray(fv, float) - y0) / (y1 - y0) * (
            height - top - bottom)
        return np.stack([xs, ys], axis=-1).round().astype(np.int32)

    y_top, y_bottom = top, height - bottom
    cv2.putText(img, "FFR pullback (model estimate, research use)", (4, 17), font, 0.5, ink,
                1, cv2.LINE_AA)
    report = getattr(rec, "lesions", None)
    for les in getattr(report, "lesions", ()):  # behind everything else
        n = les.narrowing
        a, b = px(np.array([n.start_s_mm, n.end_s_mm]), np.full(2, y0))
        cv2.rectangle(img, (int(a[0]), y_top), (max(int(b[0]), int(a[0]) + 1), y_bottom),
                      FFR_LESION, -1)
        label = str(les.number)
        w = cv2.getTextSize(label, font, 0.45, 2)[0][0]
        cv2.putText(img, label, ((int(a[0]) + int(b[0])) // 2 - w // 2, y_top - 4), font,
                    0.45, FFR_CUT, 2, cv2.LINE_AA)
    step = 0.05 if y0 >= 0.5 else 0.1
    for yv in np.arange(np.ceil(y0 / step - 1e-9) * step, 1.0 + 1e-9, step):
        y = int(px(np.array([x0]), np.array([yv]))[0, 1])
        cv2.line(img, (left, y), (width - right, y), (235, 235, 235), 1)
        if abs(yv - FFR_CUTOFF) > 0.02:  # the cut-off is labelled in its own colour
            cv2.putText(img, f"{yv:.2f}", (left - 44, y + 5), font, 0.48, grey, 1,
                        cv2.LINE_AA)
    if has_ci:  # the 95 % interval: a filled band between its low and high pullbacks
        poly = np.concatenate([px(s, np.asarray(ffr.ffr_hi, float)),
                               px(s[::-1], np.asarray(ffr.ffr_lo, float)[::-1])])
        cv2.fillPoly(img, [poly], FFR_INTERVAL, cv2.LINE_AA)
    y_cut = int(px(np.array([x0]), np.array([FFR_CUTOFF]))[0, 1])
    cv2.line(img, (left, y_cut), (width - right, y_cut), FFR_CUT, 1)  # horizontal: no anti-aliasing
    cv2.putText(img, f"{FFR_CUTOFF:.2f}", (left - 44, y_cut + 5), font, 0.48, FFR_CUT, 2,
                cv2.LINE_AA)
    for row in band:
        _dashed(img, px(s, row), FFR_BAND)
    cv2.polylines(img, [px(s, values)], False, FFR_CURVE, 2, cv2.LINE_AA)
    cv2.rectangle(img, (left, y_top), (width - right, y_bottom), (120, 120, 120), 1)
    x_step = _nice_step(x1 - x0, 6)
    for xv in np.arange(np.ceil(x0 / x_step) * x_step, x1 + 1e-9, x_step):
        x = int(px(np.array([xv]), np.array([y0]))[0, 0])
        cv2.putText(img, f"{xv:g}", (x - 8, y_bottom + 17), font, 0.48, grey, 1, cv2.LINE_AA)
    cv2.putText(img, "distance along the 3D centerline (mm)", (left, y_bottom + 34), font,
                0.46, ink, 1, cv2.LINE_AA)
    ci = ffr.ci95
    distal = f"FFR (model estimate): distal {ffr.distal:.2f}" + (
        "" if ci is None else f" (95 % {ci[0]:.2f}-{ci[1]:.2f})")
    _ffr_legend(img, (6, y_bottom + 52), distal, has_ci, tuple(ffr.model.flow_band_m_s),
                len(band) > 0, FFR_CUTOFF)
    return img


def _ffr_legend(img: NDArray[np.uint8], at: tuple[int, int], curve: str, has_ci: bool,
                velocities_m_s: tuple[float, float], has_band: bool, cutoff: float) -> None:
    """The FFR chart's legend from ``at`` (x, y) px down: a sample of each line with its
    meaning (``curve``: the FFR's, with its distal value), the interval, cut-off and
    lesion on one row, the flow assumption's band below."""
    font, ink = cv2.FONT_HERSHEY_SIMPLEX, (40, 40, 40)
    x, y = at
    third = (img.shape[1] - x) // 3

    def sample(kind: str, x0: int, yy: int) -> None:
        if kind == "curve":
            cv2.line(img, (x0, yy - 4), (x0 + 24, yy - 4), FFR_CURVE, 2, cv2.LINE_AA)
        elif kind == "interval":
            cv2.rectangle(img, (x0, yy - 9), (x0 + 24, yy + 1), FFR_INTERVAL, -1)
        elif kind == "lesion":
            cv2.rectangle(img, (x0, yy - 9), (x0 + 24, yy + 1), FFR_LESION, -1)
        elif kind == "cut":
            cv2.line(img, (x0, yy - 4), (x0 + 24, yy - 4), FFR_CUT, 1)
        elif kind == "band":
            _dashed(img, np.array([[x0, yy - 4], [x0 + 26, yy - 4]]), FFR_BAND, 7.0, 4.0)

    rows = [[("curve", curve)],
            [("interval" if has_ci else "", "95 % interval" if has_ci else "(no interval)"),
             ("cut", f"{cutoff:.2f} cut-off"), ("lesion", "lesion")]]
    if has_band:
        v0, v1 = velocities_m_s
    rows.append([("band", f"flow assumption {v0:g}-{v1:g} m/s, not a confidence "
                              "interval")])
    for k, row in enumerate(rows):
        yy = y + 17 * k
        for j, (kind, text) in enumerate(row):
            x0 = x + j * third
            sample(kind, x0, yy)
            cv2.putText(img, text, (x0 + 30, yy), font, 0.46, ink, 1, cv2.LINE_AA)
