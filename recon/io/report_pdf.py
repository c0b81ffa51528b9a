"""The report (report.pdf) of a whole reconstruction, drawn with matplotlib.

Page 1, the overview: the files' names and acquisition angles, the software version
and "research use only"; both angiograms with every segment's trace (one colour per
segment) and each lesion's MLD numbered ("LAD 1"); a 3D snapshot of every centerline
coloured by lumen diameter (seen as in view A); a table of every segment (length,
MLD, % diameter stenosis, lesion length, each with its 95 % interval, and its
lesions, and its FFR with its interval); the bifurcations (Medina class, angles, the three
segments' % diameter stenosis); the best next view; the warnings.

Then one page per segment: its diameter profile (measured, smoothed, the reference, the
diameter's 95 % band) with bands for each lesion (numbered), a borderline narrowing, a
narrowing not confirmed, the zones at the clicked ends or the ostium, where a side
branch leaves it and where one view's radius was replaced because another vessel
overlaps it; its FFR (:mod:`recon.lumen.ffr`, a model estimate for research): the distal
value with its 95 % interval and the band over the assumed flow, said not to be a
confidence interval, and the pullback chart (FFR along the segment on the profile's
distance scale, its 95 % interval shaded, the flow band dashed, a line at 0.80, the
lesions), or "FFR not computed" with the warning's reason; its figures with their 95 %
intervals; its lesions, each with MLD, % diameter stenosis, length and site, and their
intervals; and whether the most severe lesion stands out (:mod:`recon.lumen.lesions`).

No patient name, ID or date unless ``identify`` (then read from the DICOM headers).
:func:`write_report_pdf` is the page's call; the command line's ``--report`` renders
:func:`report_pdf_bytes` into the output set.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from recon import __version__
from recon.lumen.ffr import RESEARCH_NOTE
from recon.lumen.measure import MIN_LESION_DS_PCT

if TYPE_CHECKING:
    from recon.lumen.ffr import FFRResult
    from recon.pipeline import Reconstruction
    from recon.tree import TreeReconstruction

__all__ = ["report_figure", "report_pages", "report_pdf_bytes", "write_report_pdf",
           "side_branch_bands", "ffr_line", "ffr_not_computed"]

A4_IN = (8.27, 11.69)
#: One colour per segment (the seeds' order), as matplotlib's tab10.
SEGMENT_COLOURS = ("tab:orange", "tab:blue", "tab:green", "tab:red", "tab:purple",
                   "tab:brown", "tab:pink", "tab:olive", "tab:cyan", "tab:gray")
#: The FFR cut-off drawn on the pullback chart.
FFR_CUTOFF = 0.80
_CI_KEYS = {"mld_mm": "MLD", "diameter_stenosis_pct": "%DS",
            "lesion_length_mm": "lesion length", "segment_length_mm": "length"}


def _angles(alpha_deg: float, beta_deg: float) -> str:
    return (f"{'LAO' if alpha_deg >= 0 else 'RAO'} {abs(alpha_deg):.0f}° / "
            f"{'CRA' if beta_deg >= 0 else 'CAU'} {abs(beta_deg):.0f}°")


def _identity(path: str) -> str | None:
    """"Name, ID, study date" from a DICOM header (only with ``identify``)."""
    import pydicom

    try:
        ds = pydicom.dcmread(path, stop_before_pixels=True)
    except Exception:
        return None
    parts = [str(ds.get("PatientName", "")), str(ds.get("PatientID", "")),
             str(ds.get("StudyDate", ""))]
    return ", ".join(p for p in parts if p) or None


def _segments(result) -> list[Reconstruction]:
    """Every segment reconstructed: a tree's branches, else the one reconstruction."""
    return list(getattr(result, "branches", None) or [result])


def _name(rec: Reconstruction) -> str:
    return rec.seeds.segments[rec.options.segment].name


def _with_ci(value: float, ci: tuple[float, float] | None, fmt: str, unit: str) -> str:
    """"1.43 mm (1.27-1.60)": a figure and its 95 % interval."""
    text = f"{value:{fmt}} {unit}".rstrip()
    if ci is not None:
        text += f" ({ci[0]:{fmt}}–{ci[1]:{fmt}})"
    return text


def _ci(rec: Reconstruction, key: str) -> tuple[float, float] | None:
    iv = getattr(rec, "intervals", None)
    return None if iv is None else iv.ci95.get(key)


def side_branch_bands(result, rec: Reconstruction) -> list[dict]:
    """Where side branches leave segment ``rec`` (arc length along it): the tree's
    bifurcations whose parent it is (from J - r_J to J + r_J, the parent's stretch
    that the branch's ostium widens, :mod:`recon.lumen.bifurcation`); without them, the
    clicked features that lie on the segment (from s - D to s + 1.5 D, D the
    reference diameter there, as the viewer's chart draws them). Dicts ``name``,
    ``start_mm``, ``end_mm``."""
    name = _name(rec)
    bifs = [b for b in getattr(result, "bifurcations", ()) if b.parent == name]
    if bifs:
        return [{"name": b.branch, "start_mm": float(b.proximal_main.end_s_mm),
                 "end_mm": float(b.distal_main.start_s_mm)} for b in bifs]
    features = getattr(rec.seeds, "features", ())
    if not features or getattr(result, "bifurcations", ()):
        return []
    from recon.geometry import triangulate

    c = rec.centerline_3d
    s = np.asarray(c.s_mm, dtype=float)
    ref = np.interp(s, rec.profile.s_mm, rec.profile.reference_diameter_mm)
    X = triangulate(np.array([f.a_px for f in features], float),
                    np.array([f.b_px for f in features], float), rec.view_a, rec.view_b)
    dist = np.linalg.norm(np.asarray(c.X_world)[None, :, :] - X[:, None, :], axis=-1)
    out = []
    for k, (f, i) in enumerate(zip(features, np.argmin(dist, axis=1), strict=True)):
        d_ref = float(ref[i])
        on_vessel = dist[k, i] <= max(1.5, 2.0 * float(c.radius_mm[i]))
        if on_vessel and s[0] + d_ref <= s[i] <= s[-1] - d_ref:
            out.append({"name": f.name or "feature", "start_mm": float(max(s[i] - d_ref, s[0])),
                        "end_mm": float(min(s[i] + 1.5 * d_ref, s[-1]))})
    return out


# ------------------------------------------------------------------ page 1
def report_figure(result, image_a: NDArray | None, image_b: NDArray | None,
                  identify: bool = False) -> object:
    """The overview page (A4 portrait) as a matplotlib Figure (module docstring)."""
    from matplotlib.figure import Figure

    parts = _segments(result)
    first = parts[0]
    fig = Figure(figsize=A4_IN)
    fig.text(0.05, 0.975, "coronary3d — 3D quantitative coronary analysis", fontsize=14,
             weight="bold", va="top")
    fig.text(0.05, 0.952, f"software {__version__} · RESEARCH USE ONLY — not for diagnosis",
             fontsize=9, color="firebrick", va="top")
    lines = []
    for key, path, view in (("A", first.path_a, first.view_a), ("B", first.path_b,
                                                                 first.view_b)):
        line = f"{key}: {Path(path).name}, {_angles(view.alpha_deg, view.beta_deg)}"
        if identify:
            who = _identity(path)
            line += f" — {who}" if who else ""
        lines.append(line)
    fig.text(0.05, 0.93, "\n".join(lines), fontsize=8.5, va="top")
    for i, (key, image) in enumerate((("A", image_a), ("B", image_b))):
        ax = fig.add_axes((0.05 + i * 0.47, 0.62, 0.43, 0.25))
        _draw_view(ax, parts, key, image)
    _draw_3d(fig, parts)
    _draw_best_view(fig, first)
    _draw_segment_table(fig, parts)
    _draw_bifurcations(fig, result, top=0.34 - 0.0185 * (len(parts) + 1) - 0.042)
    warnings = list(getattr(result, "warnings", ()))
    if warnings:
        shown = warnings[:4] + ([f"… {len(warnings) - 4} more in report.json"]
                                if len(warnings) > 4 else [])
        fig.text(0.05, 0.035, "Warnings:\n" + "\n".join(_wrap(w, 150) for w in shown),
                 fontsize=6.5, va="bottom", color="darkred")
    return fig


def _wrap(text: str, width: int) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width)) or text


def _marks(rec: Reconstruction) -> list[tuple[str, NDArray]]:
    """(label, X (3,)) of each lesion's MLD of a segment ("LAD 1"), or its MLD without one."""
    c = rec.centerline_3d
    X, s = np.asarray(c.X_world, float), np.asarray(c.s_mm, float)

    def at(v: float) -> NDArray:
        return np.array([np.interp(v, s, X[:, k]) for k in range(3)])

    return [(f"{_name(rec)} {les.number}", at(les.narrowing.mld_s_mm))
            for les in rec.lesions.lesions] or [(f"{_name(rec)} MLD",
                                                 at(rec.measurements.mld_s_mm))]


def _marked(parts: list[Reconstruction]) -> list[Reconstruction]:
    """The segments whose places are marked on the images: those with a lesion (the first
    segment, for its MLD, when none has one)."""
    return [rec for rec in parts if rec.lesions.lesions] or parts[:1]


def _draw_view(ax, parts: list[Reconstruction], key: str, image: NDArray | None) -> None:
    first = parts[0]
    if image is not None:
        lo, hi = np.percentile(image, [0.5, 99.5])
        ax.imshow(image, cmap="gray", vmin=lo, vmax=hi)
    else:
        view = first.view_a if key == "A" else first.view_b
        ax.set_xlim(0, view.cols)
        ax.set_ylim(view.rows, 0)
        ax.text(0.5, 0.02, "image not given", transform=ax.transAxes, ha="center",
                fontsize=7, color="gray")
    placed: list[tuple[float, float]] = []
    for k, rec in enumerate(parts):
        colour = SEGMENT_COLOURS[k % len(SEGMENT_COLOURS)]
        cl = rec.centerline_a if key == "A" else rec.centerline_b
        geom = rec.view_a if key == "A" else rec.view_b
        ax.plot(cl.points_px[:, 0], cl.points_px[:, 1], color=colour, lw=1.0,
                label=_name(rec))
        for label, Xp in _marks(rec) if rec in _marked(parts) else ():
            c, r = geom.project(Xp[None])[0]
            ax.plot(c, r, "D", ms=4, color="magenta")
            dy = -10 - 9 * sum(abs(c - pc) < 40 and abs(r - pr) < 15 for pc, pr in placed)
            placed.append((c, r))
            ax.annotate(label, (c, r), xytext=(6, dy), textcoords="offset points",
                        color="magenta", fontsize=6.5,
                        arrowprops={"arrowstyle": "-", "color": "magenta", "lw": 0.5})
    view = first.view_a if key == "A" else first.view_b
    ax.set_title(f"{key}: {_angles(view.alpha_deg, view.beta_deg)}", fontsize=9)
    ax.legend(fontsize=6, loc="lower right", framealpha=0.6)
    ax.set_axis_off()


def _draw_3d(fig, parts: list[Reconstruction]) -> None:
    ax3 = fig.add_axes((0.05, 0.40, 0.40, 0.19))
    R = parts[0].view_a.R_view_from_world
    d_all = []
    for rec in parts:
        s = np.asarray(rec.centerline_3d.s_mm, float)
        d_all.append(np.interp(s, rec.profile.s_mm, rec.profile.diameter_smooth_mm))
    vmax = float(max(np.max(d) for d in d_all))
    sc = None
    for rec, d in zip(parts, d_all, strict=True):
        V = np.asarray(rec.centerline_3d.X_world, float) @ R.T
        sc = ax3.scatter(V[:, 0], V[:, 1], c=d, cmap="RdYlGn", s=4, vmin=0.4 * vmax, vmax=vmax)
        for label, Xp in _marks(rec) if rec in _marked(parts) else ():
            Vm = Xp @ R.T
            ax3.plot(Vm[0], Vm[1], "o", ms=7, mfc="none", mec="magenta", mew=1.5)
            ax3.annotate(label, (Vm[0], Vm[1]), xytext=(5, 5), textcoords="offset points",
                         fontsize=6, color="magenta")
    ax3.invert_yaxis()
    ax3.set_aspect("equal")
    ax3.set_title("3D, coloured by diameter (as seen in A)", fontsize=8.5)
    ax3.set_xticks([])
    ax3.set_yticks([])
    cb = fig.colorbar(sc, ax=ax3, fraction=0.05)
    cb.set_label("diameter (mm)", fontsize=7)
    cb.ax.tick_params(labelsize=7)


def _draw_best_view(fig, rec: Reconstruction) -> None:
    best = rec.optimal_view
    axt = fig.add_axes((0.55, 0.53, 0.42, 0.06))
    axt.set_axis_off()
    if best is None:
        return
    fs = best.current_foreshortening_pct
    rows = [("Foreshortening in A / B", f"{fs['a']:.0f} / {fs['b']:.0f} %"),
            ("Best next view", _angles(*best.angles_deg)),
            ("  foreshortening / overlap there",
             f"{best.foreshortening_pct:.1f} / {best.overlap_pct:.0f} %")]
    axt.set_title(f"Best next view for {_name(rec)}", fontsize=8.5, loc="left")
    table = axt.table(cellText=rows, colWidths=[0.6, 0.4], loc="upper left", cellLoc="left")
    table.auto_set_font_size(False)
    table.set_fontsize(7.5)
    table.scale(1.0, 1.2)
    axm = fig.add_axes((0.60, 0.38, 0.30, 0.11))
    score = best.foreshortening_map_pct + best.overlap_map_pct
    a, b = best.alpha_grid_deg, best.beta_grid_deg
    im = axm.imshow(score, origin="lower", cmap="viridis_r", aspect="auto",
                    extent=(a[0], a[-1], b[0], b[-1]))
    axm.plot(*best.angles_deg, "r*", ms=9)
    axm.set_xlabel("RAO − / LAO + (°)", fontsize=6.5)
    axm.set_ylabel("CAU − / CRA + (°)", fontsize=6.5)
    axm.tick_params(labelsize=6)
    axm.set_title("Foreshortening + overlap (%), ★ the best view", fontsize=7)
    fig.colorbar(im, ax=axm, fraction=0.05)


def _draw_segment_table(fig, parts: list[Reconstruction]) -> None:
    """Every segment's figures with their 95 % intervals and its lesions."""
    ax = fig.add_axes((0.05, 0.22, 0.90, 0.12))
    ax.set_axis_off()
    ax.set_title("Segments (95 % intervals in brackets)", fontsize=9, loc="left")
    header = ["Segment", "Length", "MLD", "% diameter stenosis", "Lesion length",
              "FFR (model)", "Lesions"]
    rows = []
    for rec in parts:
        m = rec.measurements
        report = rec.lesions
        lesions = ", ".join(f"{les.number}: {les.narrowing.diameter_stenosis_pct:.0f} % at "
                            f"{les.narrowing.mld_s_mm:.0f} mm" for les in report.lesions)
        if report.primary_ambiguous:
            lesions += " (no single most severe)"
        rows.append([_name(rec),
                     _with_ci(m.segment_length_mm, _ci(rec, "segment_length_mm"), ".1f", "mm"),
                     _with_ci(m.mld_mm, _ci(rec, "mld_mm"), ".2f", "mm"),
                     _with_ci(m.diameter_stenosis_pct, _ci(rec, "diameter_stenosis_pct"),
                              ".0f", "%"),
                     _with_ci(m.lesion_length_mm, _ci(rec, "lesion_length_mm"), ".1f", "mm"),
                     "not computed" if rec.ffr is None else _with_ci(rec.ffr.distal,
                                                                     rec.ffr.ci95, ".2f", ""),
                     lesions or ("none" + (" (ostium not confirmed)"
                                           if report.unsupported else ""))])
    table = ax.table(cellText=rows, colLabels=header, loc="upper left", cellLoc="left",
                     colWidths=[0.08, 0.15, 0.15, 0.14, 0.14, 0.12, 0.22])
    table.auto_set_font_size(False)
    table.set_fontsize(6.5)
    table.scale(1.0, 1.25)


def _draw_bifurcations(fig, result, top: float) -> None:
    bifs = tuple(getattr(result, "bifurcations", ()))
    ax = fig.add_axes((0.05, top - 0.08, 0.90, 0.08))
    ax.set_axis_off()
    if not bifs:
        ax.text(0, 0.8, "Bifurcations: none reconstructed (one segment)", fontsize=8)
        return
    ax.set_title("Bifurcations (Medina: 1 where that segment has ≥ 50 % diameter stenosis; "
                 "the side branch's first 10 mm\nfrom its carina, its ostium included)",
                 fontsize=8, loc="left")
    header = ["Bifurcation", "Main › side branch", "Medina", "Angle", "Proximal angle",
              "%DS proximal main", "%DS distal main", "%DS side branch"]
    rows = [[b.name, f"{b.parent} › {b.branch}", b.medina, f"{b.bifurcation_angle_deg:.0f}°",
             f"{b.proximal_angle_deg:.0f}°", f"{b.proximal_main.diameter_stenosis_pct:.0f} %",
             f"{b.distal_main.diameter_stenosis_pct:.0f} %",
             f"{b.side_branch.diameter_stenosis_pct:.0f} %"] for b in bifs]
    table = ax.table(cellText=rows, colLabels=header, loc="upper left", cellLoc="left")
    table.auto_set_font_size(False)
    table.set_fontsize(6.5)
    table.scale(1.0, 1.25)


# ------------------------------------------------------------------ a segment's page
def segment_figure(result, rec: Reconstruction) -> object:
    """One segment's page (module docstring)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=A4_IN)
    parent = rec.seeds.segments[rec.options.segment].parent
    fig.text(0.05, 0.975, f"Segment {_name(rec)}" + (f" (branch of {parent})" if parent
                                                      else ""),
             fontsize=13, weight="bold", va="top")
    fig.text(0.05, 0.952, f"coronary3d {__version__} · RESEARCH USE ONLY", fontsize=8,
             color="firebrick", va="top")
    s_mm = rec.profile.s_mm
    pad = 0.015 * float(s_mm[-1] - s_mm[0])
    xlim = (float(s_mm[0]) - pad, float(s_mm[-1]) + pad)  # both charts: one distance scale
    _draw_profile(fig.add_axes((0.09, 0.73, 0.86, 0.185)), result, rec, xlim)
    _draw_ffr(fig, rec, xlim)
    _draw_figures(fig, rec)
    _draw_lesions(fig, rec)
    return fig


def _draw_profile(ax, result, rec: Reconstruction, xlim: tuple[float, float]) -> None:
    prof = rec.profile
    m = rec.measurements
    top = float(np.max(prof.diameter_mm)) * 1.25
    lo_t, hi_t = prof.trusted_range_mm
    labels = ["ostium zone" if prof.ostium else "end zone", "end zone"]
    for (a, b), label in zip(((prof.s_mm[0], lo_t), (hi_t, prof.s_mm[-1])), labels,
                             strict=True):
        if b > a:
            ax.axvspan(a, b, color="0.92", label=label, zorder=0)
            labels[1] = "_" if label == "end zone" else labels[1]
    for band in side_branch_bands(result, rec):
        ax.axvspan(band["start_mm"], band["end_mm"], color="lightblue", alpha=0.6, zorder=0,
                   label=f"side branch {band['name']}")
    for view in ("a", "b"):
        for k, (a, b) in enumerate(rec.centerline_3d.overlap_stretches_mm(view)):
            ax.axvspan(a, b, facecolor="none", edgecolor="darkorange", hatch="///", lw=0,
                       zorder=0, label=f"view {view.upper()} radius replaced (overlap)"
                       if k == 0 else "_")
    for k, n in enumerate(rec.lesions.unsupported):
        ax.axvspan(n.start_s_mm, n.end_s_mm, facecolor="none", edgecolor="gray", hatch="..",
                   lw=0, label="narrowing not confirmed" if k == 0 else "_")
    for k, b in enumerate(rec.lesions.borderline):
        n = b.narrowing
        ax.axvspan(n.start_s_mm, n.end_s_mm, color="papayawhip", zorder=0,
                   label=f"borderline narrowing (below {MIN_LESION_DS_PCT:.0f} %, its 95 % "
                         "interval reaching it)"
                   if k == 0 else "_")
    for k, les in enumerate(rec.lesions.lesions):
        n = les.narrowing
        ax.axvspan(n.start_s_mm, n.end_s_mm, color="mistyrose", zorder=0,
                   label="lesion" if k == 0 else "_")
        ax.plot(n.mld_s_mm, n.mld_mm, "o", color="magenta", ms=5)
        ax.text(0.5 * (n.start_s_mm + n.end_s_mm), top * (0.97 - 0.06 * (k % 2)),
                str(les.number), ha="center", va="top", fontsize=9, weight="bold",
                color="crimson")
    iv = rec.intervals
    if iv is not None:
        s3 = rec.centerline_3d.s_mm
        inside = (s3 >= prof.s_mm[0]) & (s3 <= prof.s_mm[-1])
        ax.fill_between(s3[inside], 2 * iv.radius_lo_mm[inside], 2 * iv.radius_hi_mm[inside],
                        color="cornflowerblue", alpha=0.25, lw=0, label="diameter, 95 %")
    ax.plot(prof.s_mm, prof.diameter_mm, color="lightsteelblue", lw=0.8, label="measured")
    ax.plot(prof.s_mm, prof.diameter_smooth_mm, color="navy", lw=1.4, label="smoothed")
    ax.plot(prof.s_mm, prof.reference_diameter_mm, color="gray", ls="--", label="reference")
    if not m.has_lesion:
        ax.plot(m.mld_s_mm, m.mld_mm, "o", color="magenta", ms=5, label="MLD (no lesion)")
    ax.set_ylim(0.0, top)
    ax.set_xlim(*xlim)
    ax.set_xlabel("distance along the 3D centerline (mm)", fontsize=8)
    ax.set_ylabel("diameter (mm)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_title("Diameter profile", fontsize=9)
    ax.legend(fontsize=6.5, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=4,
              frameon=False)


def ffr_line(ffr: FFRResult) -> str:
    """The FFR's line on a segment's page: the distal value, its 95 % interval, and the
    band over the assumed hyperemic flow, said not to be a confidence interval."""
    ci = ffr.ci95
    v0, v1 = ffr.model.flow_band_m_s
    band = ffr.flow_band
    return (f"FFR (model estimate, research use only) {ffr.distal:.2f} "
            + (f"(95 % {ci[0]:.2f}–{ci[1]:.2f})" if ci is not None
               else "(no 95 % interval: the measurement intervals were not computed)")
            + f"; flow assumption {v0:g}–{v1:g} m/s: {band[0]:.2f}–{band[1]:.2f} "
            "(not a confidence interval)")


def ffr_not_computed(rec: Reconstruction) -> str:
    """"FFR not computed: <reason>", the reason from the reconstruction's warnings."""
    prefix = "FFR not computed: "
    reasons = [w[len(prefix):] for w in rec.warnings if w.startswith(prefix)]
    reason = reasons[0].removeprefix("FFR: ") if reasons else "no reason was recorded"
    return prefix + reason


def _draw_ffr(fig, rec: Reconstruction, xlim: tuple[float, float]) -> None:
    """The FFR's line, its pullback chart (FFR along the segment with its 95 % interval
    shaded, the flow assumption's band dashed, a line at the 0.80 cut-off, the lesions)
    and the research-use sentence; or why it was not computed."""
    ffr = getattr(rec, "ffr", None)
    if ffr is None:
        fig.text(0.05, 0.64, _wrap(ffr_not_computed(rec), 110), fontsize=8.5, va="top",
                 color="darkred")
        ax = fig.add_axes((0.09, 0.475, 0.86, 0.11), facecolor="0.97")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.text(0.5, 0.5, "no FFR pullback: the FFR was not computed", ha="center",
                va="center", fontsize=8, color="dimgray", transform=ax.transAxes)
        return
    line = ffr_line(ffr)
    cut = line.index("; flow assumption") + 1  # the value on one line, the flow's band below
    fig.text(0.05, 0.64, line[:cut] + "\n" + line[cut:].strip(), fontsize=8, va="top",
             weight="bold", linespacing=1.4)
    ax = fig.add_axes((0.09, 0.475, 0.86, 0.13))
    s = np.asarray(ffr.s_mm, float)
    for k, les in enumerate(rec.lesions.lesions):
        n = les.narrowing
        ax.axvspan(n.start_s_mm, n.end_s_mm, color="mistyrose", zorder=0,
                   label="lesion" if k == 0 else "_")
        ax.text(0.5 * (n.start_s_mm + n.end_s_mm), 1.045, str(les.number), ha="center",
                va="center", fontsize=8, weight="bold", color="crimson")
    shown = [np.asarray(ffr.ffr, float), *np.asarray(ffr.band, float)]
    if ffr.ffr_lo is not None and ffr.ffr_hi is not None:
        ax.fill_between(s, ffr.ffr_lo, ffr.ffr_hi, color="cornflowerblue", alpha=0.3, lw=0,
                        label="95 % interval")
        shown.append(np.asarray(ffr.ffr_lo, float))
    v0, v1 = ffr.model.flow_band_m_s
    for k, row in enumerate(ffr.band):
        ax.plot(s, row, ls="--", lw=0.9, color="darkorange",
                label=f"flow assumption {v0:g}–{v1:g} m/s (not a confidence interval)"
                if k == 0 else "_")
    ax.plot(s, ffr.ffr, color="navy", lw=1.5, label="FFR (model estimate)")
    ax.axhline(FFR_CUTOFF, color="crimson", ls=":", lw=1.0, label=f"{FFR_CUTOFF:.2f} cut-off")
    ax.annotate(f"{ffr.distal:.2f}", (s[-1], ffr.distal), xytext=(3, 0),
                textcoords="offset points", fontsize=7.5, color="navy", va="center",
                weight="bold", annotation_clip=False)
    low = max(0.0, np.floor(min(0.7, float(min(np.min(v) for v in shown)) - 0.03) * 20) / 20)
    ax.set_ylim(low, 1.07)  # FFR is at most 1: the room above is the lesions' numbers
    step = 0.05 if low >= 0.5 else 0.1
    ax.set_yticks(np.arange(np.ceil(low / step) * step, 1.0 + 1e-9, step))
    ax.set_xlim(*xlim)
    ax.set_xlabel("distance along the 3D centerline (mm)", fontsize=8)
    ax.set_ylabel("FFR pullback", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=6.5, loc="upper center", bbox_to_anchor=(0.5, -0.33), ncol=5,
              frameon=False)
    fig.text(0.05, 0.405, _wrap("The FFR is " + RESEARCH_NOTE + ". It must not guide "
                                "treatment.", 150),
             fontsize=7, va="top", color="firebrick")


def _draw_figures(fig, rec: Reconstruction) -> None:
    m = rec.measurements
    prof = rec.profile
    ax = fig.add_axes((0.05, 0.17, 0.45, 0.19))
    ax.set_axis_off()
    ax.set_title("Measurements (95 % interval)", fontsize=9, loc="left")
    ref_prox = float(np.interp(m.lesion_start_s_mm, prof.s_mm, prof.reference_diameter_mm))
    ref_dist = float(np.interp(m.lesion_end_s_mm, prof.s_mm, prof.reference_diameter_mm))
    rows = [
        ("Minimal lumen diameter", _with_ci(m.mld_mm, _ci(rec, "mld_mm"), ".2f", "mm")),
        ("% diameter stenosis", _with_ci(m.diameter_stenosis_pct,
                                         _ci(rec, "diameter_stenosis_pct"), ".0f", "%")),
        ("% area stenosis", _with_ci(m.area_stenosis_pct, _ci(rec, "area_stenosis_pct"),
                                     ".0f", "%")),
        ("Minimal lumen area", _with_ci(m.mla_mm2, _ci(rec, "mla_mm2"), ".2f", "mm²")),
        ("Reference diameter at the MLD", _with_ci(m.reference_diameter_mm,
                                                   _ci(rec, "reference_diameter_mm"), ".2f",
                                                   "mm")),
        ("Proximal / distal reference", f"{ref_prox:.2f} / {ref_dist:.2f} mm"),
        ("Lesion length", _with_ci(m.lesion_length_mm, _ci(rec, "lesion_length_mm"), ".1f",
                                   "mm")),
        ("Segment length", _with_ci(m.segment_length_mm, _ci(rec, "segment_length_mm"),
                                    ".1f", "mm")),
        ("MLD at", _with_ci(m.mld_s_mm, _ci(rec, "mld_s_mm"), ".1f", "mm")),
    ]
    ffr = getattr(rec, "ffr", None)
    rows.append(("FFR (model estimate, research)",
                 "not computed" if ffr is None else _with_ci(ffr.distal, ffr.ci95, ".2f", "")))
    table = ax.table(cellText=rows, colWidths=[0.5, 0.5], loc="upper left", cellLoc="left")
    table.auto_set_font_size(False)
    table.set_fontsize(7)
    table.scale(1.0, 1.25)


def _draw_lesions(fig, rec: Reconstruction) -> None:
    report = rec.lesions
    ax = fig.add_axes((0.05, 0.02, 0.90, 0.12))
    ax.set_axis_off()
    ax.set_title("Lesions (95 % interval)", fontsize=9, loc="left")
    if not report.lesions:
        ax.text(0.0, 0.9, "none", fontsize=8, va="top")
    else:
        header = ["#", "Site", "MLD", "%DS", "Length", "Found"]
        rows = []
        for les in report.lesions:
            n, ci = les.narrowing, les.ci95
            rows.append([
                str(les.number), f"{n.mld_s_mm:.1f} mm" + (f" ({n.zone})" if n.zone else ""),
                _with_ci(n.mld_mm, ci.get("mld_mm"), ".2f", "mm"),
                _with_ci(n.diameter_stenosis_pct, ci.get("diameter_stenosis_pct"), ".0f", "%"),
                _with_ci(n.length_mm, ci.get("length_mm"), ".1f", "mm"),
                "—" if les.found_fraction is None else f"{100 * les.found_fraction:.0f} %"])
        table = ax.table(cellText=rows, colLabels=header, loc="upper left", cellLoc="left",
                         colWidths=[0.04, 0.2, 0.22, 0.18, 0.2, 0.1])
        table.auto_set_font_size(False)
        table.set_fontsize(6.5)
        table.scale(1.0, 1.25)
    summary = report.summary()
    fig.text(0.54, 0.36, _wrap(summary[:1].upper() + summary[1:] + ".", 60),
             fontsize=7.5, va="top")
    fig.text(0.54, 0.26, _wrap(
        "Found: the share of the 95 % intervals' posterior draws that found a lesion on "
        "that stretch. A narrowing in the first or last 5 mm of a segment, or in a branch's "
        "ostium zone, is a lesion only when the profile past the zone shows it too; below "
        "25 % diameter stenosis a narrowing is an irregularity, not a lesion.", 75),
             fontsize=6.5, va="top", color="dimgray")


# ------------------------------------------------------------------ the document
def report_pages(result, image_a: NDArray | None, image_b: NDArray | None,
                 identify: bool = False) -> list:
    """Every page: the overview, then one per segment."""
    return [report_figure(result, image_a, image_b, identify),
            *(segment_figure(result, rec) for rec in _segments(result))]


def report_pdf_bytes(result: Reconstruction | TreeReconstruction, image_a: NDArray | None,
                     image_b: NDArray | None, identify: bool = False) -> bytes:
    """The report as PDF bytes. ``image_a``, ``image_b``: (H, W) the frames used (None: the
    traces are drawn without them)."""
    from matplotlib.backends.backend_pdf import PdfPages

    buf = io.BytesIO()
    with PdfPages(buf, metadata={"Title": "coronary3d report", "Creator": "coronary3d",
                                 "Producer": f"coronary3d {__version__}",
                                 "CreationDate": None}) as pdf:
        for fig in report_pages(result, image_a, image_b, identify):
            pdf.savefig(fig)
    return buf.getvalue()


def write_report_pdf(result: Reconstruction | TreeReconstruction, path: str | os.PathLike,
                     image_a: NDArray | None = None, image_b: NDArray | None = None,
                     identify: bool = False) -> Path:
    """Write the report of a reconstruction (one segment or a tree) to ``path``, whole or
    not at all, and return the path (the page's call)."""
    from recon.io.files import atomic_write_bytes

    atomic_write_bytes(path, report_pdf_bytes(result, image_a, image_b, identify))
    return Path(path)
