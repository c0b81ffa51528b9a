"""The one-page report (report.pdf) of a reconstruction, drawn with matplotlib.

Both angiograms with the traced centerline, the MLD and the lesion ends; a 3D
snapshot of the centerline coloured by lumen diameter (seen as in view A); the
diameter profile with the reference and the lesion; the measurements in clinical
words; the best next view; the files' names and acquisition angles, the software
version and "research use only". No patient name, ID or date unless ``identify``
(they are then read from the DICOM headers).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from recon import __version__

if TYPE_CHECKING:
    from recon.pipeline import Reconstruction

__all__ = ["report_figure", "report_pdf_bytes"]

A4_IN = (8.27, 11.69)


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


def report_figure(rec: Reconstruction, image_a: NDArray, image_b: NDArray,
                  identify: bool = False) -> object:
    """The report page as a matplotlib Figure (A4 portrait)."""
    from matplotlib.figure import Figure

    m = rec.measurements
    prof = rec.profile
    X = np.asarray(rec.centerline_3d.X_world, float)
    s = np.asarray(rec.centerline_3d.s_mm, float)
    marks = {"MLD": m.mld_s_mm}
    if m.has_lesion:
        marks.update({"lesion start": m.lesion_start_s_mm, "lesion end": m.lesion_end_s_mm})
    P = {n: np.array([np.interp(v, s, X[:, k]) for k in range(3)]) for n, v in marks.items()}

    fig = Figure(figsize=A4_IN)
    fig.text(0.05, 0.975, "coronary3d — 3D quantitative coronary analysis", fontsize=14,
             weight="bold", va="top")
    fig.text(0.05, 0.952, f"software {__version__} · RESEARCH USE ONLY — not for diagnosis",
             fontsize=9, color="firebrick", va="top")
    lines = []
    for key, path, view in (("A", rec.path_a, rec.view_a), ("B", rec.path_b, rec.view_b)):
        line = f"{key}: {Path(path).name}, {_angles(view.alpha_deg, view.beta_deg)}"
        if identify:
            who = _identity(path)
            line += f" — {who}" if who else ""
        lines.append(line)
    fig.text(0.05, 0.93, "\n".join(lines), fontsize=8.5, va="top")

    for i, (key, image, cl, geom) in enumerate((
            ("A", image_a, rec.centerline_a, rec.view_a),
            ("B", image_b, rec.centerline_b, rec.view_b))):
        ax = fig.add_axes((0.05 + i * 0.47, 0.585, 0.43, 0.285))
        lo, hi = np.percentile(image, [0.5, 99.5])
        ax.imshow(image, cmap="gray", vmin=lo, vmax=hi)
        ax.plot(cl.points_px[:, 0], cl.points_px[:, 1], color="orange", lw=1.0)
        for name, Xp in P.items():
            c, r = geom.project(Xp[None])[0]
            ax.plot(c, r, "D", ms=5, color="magenta" if name == "MLD" else "royalblue")
        c, r = geom.project(P["MLD"][None])[0]
        ax.annotate("MLD", (c, r), xytext=(-28, -4), textcoords="offset points",
                    color="magenta", fontsize=8)
        ax.set_title(f"{key}: {_angles(geom.alpha_deg, geom.beta_deg)}", fontsize=9)
        ax.set_axis_off()

    # 3D snapshot: the centerline coloured by diameter, in view A's image axes.
    ax3 = fig.add_axes((0.05, 0.33, 0.40, 0.215))
    V = X @ rec.view_a.R_view_from_world.T
    d = np.interp(s, prof.s_mm, prof.diameter_smooth_mm)
    sc = ax3.scatter(V[:, 0], V[:, 1], c=d, cmap="RdYlGn", s=6, vmin=0.5 * np.max(d),
                     vmax=np.max(d))
    Vm = P["MLD"] @ rec.view_a.R_view_from_world.T
    ax3.plot(Vm[0], Vm[1], "o", ms=9, mfc="none", mec="magenta", mew=2)
    ax3.invert_yaxis()
    ax3.set_aspect("equal")
    ax3.set_title("3D centerline, coloured by diameter (seen as in A)", fontsize=9)
    ax3.set_xticks([])
    ax3.set_yticks([])
    cb = fig.colorbar(sc, ax=ax3, fraction=0.05)
    cb.ax.set_title("mm", fontsize=7)

    axp = fig.add_axes((0.60, 0.36, 0.36, 0.20))
    axp.plot(prof.s_mm, prof.diameter_mm, color="lightsteelblue", lw=0.8, label="measured")
    axp.plot(prof.s_mm, prof.diameter_smooth_mm, color="navy", lw=1.5, label="smoothed")
    axp.plot(prof.s_mm, prof.reference_diameter_mm, color="gray", ls="--", label="reference")
    if m.has_lesion:
        axp.axvspan(m.lesion_start_s_mm, m.lesion_end_s_mm, color="mistyrose")
    axp.plot(m.mld_s_mm, m.mld_mm, "o", color="magenta")
    axp.set_xlabel("distance from the proximal end (mm)", fontsize=8)
    axp.set_ylabel("diameter (mm)", fontsize=8)
    axp.tick_params(labelsize=7)
    axp.legend(fontsize=7, loc="lower left")
    axp.set_title("Diameter profile", fontsize=9)

    ref_prox = float(np.interp(m.lesion_start_s_mm, prof.s_mm, prof.reference_diameter_mm))
    ref_dist = float(np.interp(m.lesion_end_s_mm, prof.s_mm, prof.reference_diameter_mm))
    rows = [
        ("Minimal lumen diameter", f"{m.mld_mm:.2f} mm"),
        ("% diameter stenosis", f"{m.diameter_stenosis_pct:.0f} %"),
        ("% area stenosis", f"{m.area_stenosis_pct:.0f} %"),
        ("Minimal lumen area", f"{m.mla_mm2:.2f} mm²"),
        ("Reference diameter at the MLD", f"{m.reference_diameter_mm:.2f} mm"),
        ("Proximal / distal reference", f"{ref_prox:.2f} / {ref_dist:.2f} mm"),
        ("Lesion length", f"{m.lesion_length_mm:.1f} mm"),
        ("Segment length", f"{m.segment_length_mm:.1f} mm"),
    ]
    best = rec.optimal_view
    if best is not None:
        fs = best.current_foreshortening_pct
        rows += [("Foreshortening in A / B", f"{fs['a']:.0f} / {fs['b']:.0f} %"),
                 ("Best next view (★ on the map)", _angles(*best.angles_deg)),
                 ("  foreshortening / overlap there",
                  f"{best.foreshortening_pct:.1f} / {best.overlap_pct:.0f} %")]
    axt = fig.add_axes((0.05, 0.05, 0.50, 0.24))
    axt.set_axis_off()
    table = axt.table(cellText=rows, colWidths=[0.55, 0.45], loc="upper left",
                      cellLoc="left")
    table.auto_set_font_size(False)
    table.set_fontsize(8)
    table.scale(1.0, 1.3)
    if best is not None:
        axm = fig.add_axes((0.62, 0.07, 0.33, 0.19))
        score = best.foreshortening_map_pct + best.overlap_map_pct
        a, b = best.alpha_grid_deg, best.beta_grid_deg
        im = axm.imshow(score, origin="lower", cmap="viridis_r", aspect="auto",
                        extent=(a[0], a[-1], b[0], b[-1]))
        axm.plot(*best.angles_deg, "r*", ms=10)
        axm.set_xlabel("RAO − / LAO + (°)", fontsize=7)
        axm.set_ylabel("CAU − / CRA + (°)", fontsize=7)
        axm.tick_params(labelsize=6)
        axm.set_title("Foreshortening + overlap (%)", fontsize=8)
        fig.colorbar(im, ax=axm, fraction=0.05)
    return fig


def report_pdf_bytes(rec: Reconstruction, image_a: NDArray, image_b: NDArray,
                     identify: bool = False) -> bytes:
    """The report as PDF bytes. ``image_a``, ``image_b``: (H, W) the frames used."""
    from matplotlib.backends.backend_pdf import PdfPages

    fig = report_figure(rec, image_a, image_b, identify)
    buf = io.BytesIO()
    with PdfPages(buf, metadata={"Title": "coronary3d report", "Creator": "coronary3d",
                                 "Producer": f"coronary3d {__version__}",
                                 "CreationDate": None}) as pdf:
        pdf.savefig(fig)
    return buf.getvalue()
