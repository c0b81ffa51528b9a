"""The panels' texts: markdown made from the loaded pair, the marks and the results.

Pure functions (no viser): the case table, the marks summary, the
calibration table and the results tables, plus the texts shown before any
calibration or reconstruction.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from recon.geometry import MIN_VIEW_SEPARATION_DEG, view_separation_deg

if TYPE_CHECKING:
    from recon.geometry import ViewGeometry
    from recon.pipeline import Reconstruction
    from recon.pose.calibration import CalibrationResult
    from recon.types import Angiogram
    from viewer_app.state import MarkState

__all__ = [
    "NOT_CALIBRATED_TEXT",
    "NO_RECONSTRUCTION_TEXT",
    "angle_text",
    "bifurcations_markdown",
    "branch_stretches",
    "calibration_doubts",
    "calibration_markdown",
    "clinical_markdown",
    "close_views_warning",
    "lesion_measurements",
    "lesions_lines",
    "ffr_note",
    "ffr_rows",
    "fmt",
    "info_markdown",
    "input_warning_lines",
    "marks_markdown",
    "results_markdown",
    "segments_lines",
    "warnings_markdown",
]

NO_RECONSTRUCTION_TEXT = "No reconstruction yet."
NOT_CALIBRATED_TEXT = (
    "Not calibrated: epipolar lines use the header geometry.\n\n"
    "Tip: landmarks spread over the image (branch points and vessel ends far "
    "from the lesion) fix view B's pose better than clicks near the lesion "
    "(`coronary3d bench calibration`, landmark rows)."
)


def angle_text(alpha_deg: float, beta_deg: float) -> str:
    """C-arm angles as a clinician reads them, e.g. ``"RAO 29.3° / CRA 25.5°"``."""
    a = f"{'LAO' if alpha_deg >= 0 else 'RAO'} {abs(alpha_deg):.1f}°"
    b = f"{'CRA' if beta_deg >= 0 else 'CAU'} {abs(beta_deg):.1f}°"
    return f"{a} / {b}"


def fmt(value: object) -> str:
    """A table cell: floats to 3 significant digits (large ones whole), lists comma-joined."""
    if isinstance(value, float | np.floating):
        return f"{float(value):.3g}" if abs(float(value)) < 1e4 else f"{float(value):.0f}"
    if isinstance(value, list | tuple):
        return ", ".join(fmt(v) for v in value)
    return str(value)


def info_markdown(angio_a: Angiogram, angio_b: Angiogram, name_a: str, name_b: str) -> str:
    """The case table: file, angles, SID / SOD, size and frame of views A and B, the
    angle between the views, and a warning when they are too close to fix depth."""
    rows = ["| | A | B |", "| --- | --- | --- |"]
    ga, gb = angio_a.geometry, angio_b.geometry
    rows.append(f"| file | {name_a} | {name_b} |")
    rows.append(f"| angles | {angle_text(ga.alpha_deg, ga.beta_deg)} | "
                f"{angle_text(gb.alpha_deg, gb.beta_deg)} |")
    rows.append(f"| SID / SOD (mm) | {ga.sid_mm:.0f} / {ga.sod_mm:.0f} | "
                f"{gb.sid_mm:.0f} / {gb.sod_mm:.0f} |")
    rows.append(f"| size | {ga.cols}×{ga.rows} | {gb.cols}×{gb.rows} |")
    rows.append(f"| frame | {angio_a.frame_index + 1}/{angio_a.n_frames} | "
                f"{angio_b.frame_index + 1}/{angio_b.n_frames} |")
    separation = view_separation_deg(ga, gb)
    rows.append(f"\nViews {separation:.0f}° apart.")
    rows += [f"\n⚠ {w}" for w in input_warning_lines(angio_a, angio_b)]
    warning = close_views_warning(ga, gb)
    if warning is not None:
        rows.append(f"⚠ **Views too similar**: {warning}")
    return "\n".join(rows)


def input_warning_lines(angio_a: Angiogram, angio_b: Angiogram) -> list[str]:
    """What the files themselves make less certain, one line each, as the reconstruction
    will report it (recon.pipeline.input_warnings: an 8-bit, lossy or display-processed
    image's radii)."""
    from recon.pipeline import input_warnings

    return (input_warnings(getattr(angio_a, "info", {}), "A")
            + input_warnings(getattr(angio_b, "info", {}), "B"))


def warnings_markdown(result: object) -> str:
    """The reconstruction's warnings a clinician must read with its figures (report.json
    ``warnings``: the inputs, the views' separation, stretches the cross-view check
    flagged, a bifurcation's doubtful origin) and a calibration that does not fit the
    clicks (:func:`calibration_doubts`); "" when there is none."""
    lines = list(dict.fromkeys([*getattr(result, "warnings", ()),
                                *calibration_doubts(getattr(result, "calibration", None))]))
    if not lines:
        return ""
    return "\n".join(["**Read with these figures:**", ""] + [f"- ⚠ {w}" for w in lines])


def close_views_warning(view_a: ViewGeometry, view_b: ViewGeometry) -> str | None:
    """The warning for two views whose central rays are less than
    :data:`recon.geometry.MIN_VIEW_SEPARATION_DEG` apart (the separation the
    reconstruction refuses, :func:`recon.geometry.view_separation_deg`); None otherwise."""
    separation = view_separation_deg(view_a, view_b)
    if separation >= MIN_VIEW_SEPARATION_DEG:
        return None
    return (f"the views are {separation:.0f}° apart and at least "
            f"{MIN_VIEW_SEPARATION_DEG:.0f}° are needed to fix depth; Reconstruct will "
            "refuse this pair. Open two views further apart.")


def marks_markdown(state: MarkState, last_click_ms: float, autosave_path: str | Path) -> str:
    """The marks summary: counts, what is still missing, the last warning, click time, autosave."""
    seeds = state.to_seeds()
    lines = [f"**{len(state.marks)} marks**: {len(seeds.segments)} complete segment(s), "
             f"{len(seeds.features)} feature pair(s)."]
    lines += segments_lines(state)
    lines += [f"- {m}" for m in state.missing()[:6]]
    if state.last_message:
        lines.append(f"- ⚠ {state.last_message}")
    if np.isfinite(last_click_ms):
        lines.append(f"\nLast click → epipolar line: {last_click_ms:.1f} ms (server).")
    lines.append(f"\nAutosave: `{autosave_path}`")
    return "\n".join(lines)


def segments_lines(state: MarkState) -> list[str]:
    """One line per segment when there are several: its name (the current one marked),
    and for a branch the segment it leaves and the landmark where it leaves it."""
    if len(state.segment_names) < 2:
        return []
    lines = ["\nSegments (the tree):"]
    for k, name in enumerate(state.segment_names):
        shown = f"**{name}** (current)" if k == state.current_segment else name
        link = state.parent_of(name)
        lines.append(f"- {shown}" + ("" if link is None else
                                      f" ↳ branch of {link[0]} at landmark {link[1]}"))
    return lines


def calibration_doubts(res: CalibrationResult | None) -> list[str]:
    """The calibration's warnings that put every figure in doubt: a clicked
    correspondence still far off after calibration, or a pose correction larger than a
    header is ever wrong by. Both come of a click on the wrong place or two landmarks
    paired wrongly (recon.pose.calibration)."""
    return [w for w in getattr(res, "warnings", ()) if " still " in w or "implausible" in w]


def calibration_markdown(res: CalibrationResult) -> str:
    """Reprojection error before / after, view B's pose correction, iterations, warnings."""
    rot_deg = float(np.degrees(np.linalg.norm(np.asarray(res.rotvec, float))))
    t_mm = np.asarray(res.t_mm, dtype=float)
    lines = [
        "| | before | after |",
        "| --- | --- | --- |",
        f"| error (px) | {res.error_before_px:.2f} | {res.error_after_px:.2f} |",
        f"| error (mm) | {res.error_before_mm:.2f} | {res.error_after_mm:.2f} |",
        "",
        f"Pose correction of B: **{rot_deg:.2f}°** rotation, **{np.linalg.norm(t_mm):.2f} mm**"
        f" translation ({', '.join(f'{x:.2f}' for x in t_mm)} mm); "
        f"{res.iterations} iterations, {res.elapsed_ms:.0f} ms.",
    ]
    for w in getattr(res, "warnings", ()):
        found = re.match(r"underdetermined: (\d+) features", w)
        if found:  # expected with few landmarks: guidance, not an alarm
            k = int(found.group(1))
            lines.append(f"- ℹ {k} correspondences (the 2 segment ends + {k - 2} landmark "
                         f"pair(s)): with 5 or more the images alone fix view B's pose; "
                         f"with fewer the header's expected accuracy fills in. Add "
                         f"{5 - k} landmark pair(s) (branch points) to firm it up.")
        else:
            lines.append(f"- ⚠ {w}")
    return "\n".join(lines)


def results_markdown(rec: Reconstruction) -> str:
    """3D measurements, the Table-3 metrics (per-view sub-tables side by side) and timings."""
    rows = ["| measurement | value |", "| --- | --- |"]
    ci = rec.intervals.ci95 if getattr(rec, "intervals", None) is not None else {}
    rows += [f"| {k} | {fmt(v)}" + (f" ({fmt(ci[k][0])}-{fmt(ci[k][1])})" if k in ci else "")
             + " |" for k, v in rec.measurements.to_dict().items()]
    for view, other in (("a", "B"), ("b", "A")):
        stretches = rec.centerline_3d.overlap_stretches_mm(view)
        if stretches:
            where = ", ".join(f"{a:.1f}-{b:.1f}" for a, b in stretches)
            rows.append(f"| view {view.upper()} overlapped: radius from view {other} "
                        f"| {where} mm |")
    metrics = dict(rec.metrics)
    per_view = {k: metrics.pop(k) for k in list(metrics) if isinstance(metrics[k], dict)}
    if per_view:
        names = list(per_view)
        keys = [k for k in per_view[names[0]] if all(k in per_view[n] for n in names)]
        rows += ["", "| Table 3 | " + " | ".join(f"view {n.upper()}" for n in names) + " |",
                 "| --- |" + " --- |" * len(names)]
        rows += [f"| {k} | " + " | ".join(fmt(per_view[n][k]) for n in names) + " |"
                 for k in keys]
    rows += ["", "| Table 3 (both views) | value |", "| --- | --- |"]
    rows += [f"| {k} | {fmt(v)} |" for k, v in metrics.items()]
    rows += ["", "| stage | ms |", "| --- | --- |"]
    rows += [f"| {k} | {fmt(v)} |" for k, v in rec.timings_ms.items()]
    return "\n".join(rows)


def lesion_measurements(profile: object, start_mm: float, end_mm: float,
                        reference_mm: tuple[float, float] | None = None) -> dict[str, float]:
    """2D-QCA style measurements for lesion ends (and reference sites) the clinician placed.

    The reference diameter runs linearly, along the vessel, from the (smoothed)
    diameter at the proximal reference site to that at the distal one (the
    user-defined reference of 2D QCA); the sites are the lesion ends unless
    ``reference_mm`` = (proximal, distal) mm gives them. The MLD is the smallest
    smoothed diameter between the lesion ends. ``profile`` is a
    recon.lumen.measure.LumenProfile (``s_mm``, ``diameter_smooth_mm``, (M,) arrays). Returns a
    dict with the keys of :class:`recon.lumen.measure.Measurements` that depend on the lesion
    ends, plus ``proximal_reference_mm``, ``distal_reference_mm`` and the sites
    ``proximal_reference_s_mm``, ``distal_reference_s_mm``.
    """
    s = np.asarray(profile.s_mm, dtype=float)
    d = np.asarray(profile.diameter_smooth_mm, dtype=float)

    def inside(x: float) -> float:
        return float(np.clip(x, s[0], s[-1]))

    lo, hi = sorted((inside(start_mm), inside(end_mm)))
    ref_lo, ref_hi = (lo, hi) if reference_mm is None else sorted(map(inside, reference_mm))
    within = (s >= lo) & (s <= hi)
    if not np.any(within):
        within[int(np.argmin(np.abs(s - lo)))] = True
    idx = np.flatnonzero(within)
    i_mld = int(idx[np.argmin(d[idx])])
    d_prox, d_dist = float(np.interp(ref_lo, s, d)), float(np.interp(ref_hi, s, d))
    frac = 0.0 if ref_hi <= ref_lo else (s[i_mld] - ref_lo) / (ref_hi - ref_lo)
    ref = d_prox + frac * (d_dist - d_prox)
    mld = float(d[i_mld])
    return {
        "mld_mm": mld,
        "mld_s_mm": float(s[i_mld]),
        "reference_diameter_mm": ref,
        "proximal_reference_mm": d_prox,
        "distal_reference_mm": d_dist,
        "proximal_reference_s_mm": ref_lo,
        "distal_reference_s_mm": ref_hi,
        "diameter_stenosis_pct": 100.0 * (1.0 - mld / ref),
        "area_stenosis_pct": 100.0 * (1.0 - (mld / ref) ** 2),
        "mla_mm2": float(np.pi * mld**2 / 4.0),
        "lesion_start_s_mm": lo,
        "lesion_end_s_mm": hi,
        "lesion_length_mm": hi - lo,
    }


def branch_stretches(rec: Reconstruction) -> list[dict[str, float | str]]:
    """Stretches of the segment where a side branch leaves it, from the clicked features.

    A feature (clicked in both views) is triangulated with the reconstruction's
    geometry; when it lies on the segment (within the larger of 1.5 mm and twice the
    local radius of the 3D centerline), at least one reference diameter D from either
    end, it is a branch point at arc length s. There the side branch's ostium widens the
    vessel's silhouette in both views, so the measured diameter from s - D to s + 1.5 D
    (the branch leaves distally) is the main vessel plus part of the branch. Returns
    dicts ``name``, ``s_mm``, ``start_mm``, ``end_mm``, proximal first.
    """
    from recon.geometry import triangulate

    features = getattr(rec.seeds, "features", ())
    if not features:
        return []
    c = rec.centerline_3d
    s = np.asarray(c.s_mm, dtype=float)
    ref = np.asarray(rec.profile.reference_diameter_mm, dtype=float)
    X = triangulate(np.array([f.a_px for f in features], float),
                    np.array([f.b_px for f in features], float), rec.view_a, rec.view_b)
    dist = np.linalg.norm(np.asarray(c.X_world)[None, :, :] - X[:, None, :], axis=-1)
    nearest = np.argmin(dist, axis=1)
    out = []
    for f, i, d_mm in zip(features, nearest, dist[np.arange(len(features)), nearest],
                          strict=True):
        d_ref = float(ref[i])
        on_vessel = d_mm <= max(1.5, 2.0 * float(c.radius_mm[i]))
        if on_vessel and s[0] + d_ref <= s[i] <= s[-1] - d_ref:
            out.append({"name": f.name or "feature", "s_mm": float(s[i]),
                        "start_mm": float(max(s[i] - d_ref, s[0])),
                        "end_mm": float(min(s[i] + 1.5 * d_ref, s[-1]))})
    return sorted(out, key=lambda b: b["s_mm"])


def bifurcations_markdown(tree: object) -> str:
    """The bifurcation QCA of a tree (recon.tree.TreeReconstruction ``bifurcations``), a
    column per bifurcation: its vessels, Medina class, angles, and the reference diameter
    and % diameter stenosis of its proximal main, distal main and side branch."""
    bifs = tuple(getattr(tree, "bifurcations", ()))
    if not bifs:
        return ""

    def row(label: str, cells: list[str]) -> str:
        return f"| {label} | " + " | ".join(cells) + " |"

    parts = (("proximal main", "proximal_main"), ("distal main", "distal_main"),
             ("side branch", "side_branch"))
    rows = ["**Bifurcations** (Medina p,d,s: 1 where the proximal main, distal main, side "
            "branch has ≥ 50 % diameter stenosis)", "",
            row("", [b.name for b in bifs]), "| --- |" + " --- |" * len(bifs),
            row("main › side branch", [f"{b.parent} › {b.branch}" for b in bifs]),
            row("Medina", [f"**{b.medina}**" for b in bifs]),
            row("Bifurcation angle", [f"{b.bifurcation_angle_deg:.0f}°" for b in bifs]),
            row("Proximal angle", [f"{b.proximal_angle_deg:.0f}°" for b in bifs])]
    for label, key in parts:
        rows.append(row(f"Reference diameter, {label}",
                        [f"{getattr(b, key).reference_diameter_mm:.2f} mm" for b in bifs]))
    for label, key in parts:
        rows.append(row(f"% diameter stenosis, {label}",
                        [f"{getattr(b, key).diameter_stenosis_pct:.0f} %" for b in bifs]))
    doubts = [f"- ⚠ {b.origin_warning}" for b in bifs if getattr(b, "origin_warning", None)]
    return "\n".join(rows + ([""] + doubts if doubts else []))


def _with_ci(text: str, key: str, ci: dict, digits: int) -> str:
    """``text`` followed by the 95 % interval of ``key`` when there is one."""
    if key not in ci:
        return text
    lo, hi = ci[key]
    return f"{text} ({lo:.{digits}f}–{hi:.{digits}f})"


def clinical_markdown(rec: Reconstruction, lesion: dict[str, float] | None = None) -> str:
    """The results a clinician reads, with labels and units; the foreshortening of the
    segment in both views and the best next view when the reconstruction has them.

    ``lesion``: measurements for lesion ends (and reference sites) the clinician moved
    (:func:`lesion_measurements`); None: the automatic analysis.
    """
    m = rec.measurements
    prof = rec.profile
    s = np.asarray(prof.s_mm, dtype=float)
    ref_curve = np.asarray(prof.reference_diameter_mm, dtype=float)
    if lesion is None:
        v = {k: float(getattr(m, k)) for k in (
            "mld_mm", "mld_s_mm", "reference_diameter_mm", "diameter_stenosis_pct",
            "area_stenosis_pct", "mla_mm2", "lesion_start_s_mm", "lesion_end_s_mm",
            "lesion_length_mm")}
        v["proximal_reference_s_mm"] = v["lesion_start_s_mm"]
        v["distal_reference_s_mm"] = v["lesion_end_s_mm"]
        v["proximal_reference_mm"] = float(np.interp(v["lesion_start_s_mm"], s, ref_curve))
        v["distal_reference_mm"] = float(np.interp(v["lesion_end_s_mm"], s, ref_curve))
        source = "automatic lesion detection" if m.has_lesion else "no lesion found"
    else:
        v, source = lesion, "lesion ends set by hand"
    # The 95 % intervals are those of the automatic analysis (report.json
    # measurements_ci95); lesion ends set by hand have none, and the segment length
    # does not depend on them.
    ci_all = rec.intervals.ci95 if getattr(rec, "intervals", None) is not None else {}
    ci = ci_all if lesion is None else {}
    mld = _with_ci(f"**{v['mld_mm']:.2f} mm**", "mld_mm", ci, 2)
    ds = _with_ci(f"**{v['diameter_stenosis_pct']:.0f} %**", "diameter_stenosis_pct", ci, 0)
    rows = [f"**3D QCA** ({source}" + ("; 95 % intervals in brackets" if ci else "") + ")",
            "", "| | |", "| --- | --- |",
            f"| Minimal lumen diameter | {mld} |",
            f"| % diameter stenosis | {ds} |",
            "| % area stenosis | "
            + _with_ci(f"{v['area_stenosis_pct']:.0f} %", "area_stenosis_pct", ci, 0) + " |",
            "| Minimal lumen area | "
            + _with_ci(f"{v['mla_mm2']:.2f} mm²", "mla_mm2", ci, 2) + " |",
            "| Reference diameter at the MLD | "
            + _with_ci(f"{v['reference_diameter_mm']:.2f} mm", "reference_diameter_mm", ci, 2)
            + " |",
            f"| Proximal / distal reference | {v['proximal_reference_mm']:.2f} / "
            f"{v['distal_reference_mm']:.2f} mm (at {v['proximal_reference_s_mm']:.1f} / "
            f"{v['distal_reference_s_mm']:.1f} mm) |",
            "| Lesion length | "
            + _with_ci(f"{v['lesion_length_mm']:.1f} mm", "lesion_length_mm", ci, 1)
            + f", from {v['lesion_start_s_mm']:.1f} to {v['lesion_end_s_mm']:.1f} mm |",
            f"| MLD position | {v['mld_s_mm']:.1f} mm from the proximal end |",
            "| Segment length | "
            + _with_ci(f"{m.segment_length_mm:.1f} mm", "segment_length_mm", ci_all, 1) + " |",
            *ffr_rows(rec)]
    best = getattr(rec, "optimal_view", None)
    if best is not None:
        fs = best.current_foreshortening_pct
        rows.append(f"| Foreshortening in A / B | {fs['a']:.0f} / {fs['b']:.0f} % |")
        # The map knows only this segment, not the vessels around it (bench optimal-view
        # measures how often they cross it at the recommended angle).
        rows.append(f"| Best next view | **{angle_text(*best.angles_deg)}** "
                    f"(foreshortening {best.foreshortening_pct:.1f} %, the segment over "
                    f"itself {best.overlap_pct:.0f} %; other vessels are not traced: check "
                    "that none crosses it there) |")
    if lesion is None:
        rows += lesions_lines(rec)
    rows += _caveats(rec, v)
    return "\n".join(rows)


def ffr_rows(rec: Reconstruction) -> list[str]:
    """The FFR's rows of the clinical table (recon.lumen.ffr, a model estimate for
    research): the distal value with its 95 % interval and the band over the assumed
    flow, said not to be a confidence interval; or why it was not computed."""
    from recon.io.report_pdf import ffr_not_computed

    ffr = getattr(rec, "ffr", None)
    if ffr is None:
        reason = ffr_not_computed(rec).removeprefix("FFR not computed: ")
        return [f"| FFR (model estimate for research) | not computed: {reason} |"]
    ci = ffr.ci95
    v0, v1 = ffr.model.flow_band_m_s
    lo, hi = ffr.flow_band
    return [f"| FFR, distal (model estimate for research) | **{ffr.distal:.2f}**"
            + (f" (95 % {ci[0]:.2f}–{ci[1]:.2f})" if ci is not None else
               " (no 95 % interval)") + " |",
            f"| FFR over the flow assumption ({v0:g}–{v1:g} m/s) | {lo:.2f}–{hi:.2f}, not a "
            "confidence interval |"]


def ffr_note(rec: Reconstruction) -> str:
    """The lines beside the FFR chart: that the FFR is a model estimate for research, not
    validated against a pressure wire; or, with no FFR, why it was not computed."""
    from recon.io.report_pdf import ffr_not_computed
    from recon.lumen.ffr import RESEARCH_NOTE

    if getattr(rec, "ffr", None) is None:
        return f"⚠ **{ffr_not_computed(rec)}**"
    return (f"⚠ **Research use only.** The FFR is {RESEARCH_NOTE}. It must not guide "
            "treatment. Blue band: its 95 % interval (the geometry's uncertainty); orange "
            "dashes: the FFR at the lowest and highest assumed hyperemic flow, which is "
            "not a confidence interval.")


def lesions_lines(rec: Reconstruction) -> list[str]:
    """Every lesion of the segment (recon.lumen.lesions: every narrowing that passes the
    lesion criterion, proximal to distal), each with its MLD, % diameter stenosis and
    length and their 95 % intervals, and whether the most severe stands out (the table
    above is of that one); [] for a result without them."""
    report = getattr(rec, "lesions", None)
    if report is None:
        return []
    lines = ["", f"**Lesions**: {report.summary()}."]
    if len(report.lesions) < 2:
        return lines
    lines += ["", "| lesion | MLD at | MLD | % DS | length |", "| --- | --- | --- | --- | --- |"]
    for k, les in enumerate(report.lesions):
        n, ci = les.narrowing, dict(les.ci95)
        mark = " (table above)" if k == report.primary else ""
        lines.append(
            f"| {les.number}{mark} | {n.mld_s_mm:.1f} mm | "
            f"{_with_ci(f'{n.mld_mm:.2f} mm', 'mld_mm', ci, 2)} | "
            f"{_with_ci(f'{n.diameter_stenosis_pct:.0f} %', 'diameter_stenosis_pct', ci, 0)} | "
            f"{_with_ci(f'{n.length_mm:.1f} mm', 'length_mm', ci, 1)} |")
    return lines


def _caveats(rec: Reconstruction, v: dict[str, float]) -> list[str]:
    """Lines under the table: the stretches whose diameter is not the lumen's alone."""
    lines = []
    sites = {"proximal": v["proximal_reference_s_mm"], "distal": v["distal_reference_s_mm"]}

    def in_it(lo: float, hi: float) -> str:
        names = [k for k, s_mm in sites.items() if lo <= s_mm <= hi]
        return (f"; **the {' and '.join(names)} reference site is in it: move it out**"
                if names else "")

    for b in branch_stretches(rec):
        inside = b["start_mm"] <= v["mld_s_mm"] <= b["end_mm"] or (
            v["lesion_start_s_mm"] <= b["end_mm"] and b["start_mm"] <= v["lesion_end_s_mm"])
        lines.append(f"- Side branch at {b['s_mm']:.1f} mm ({b['name']}): the diameter from "
                     f"{b['start_mm']:.1f} to {b['end_mm']:.1f} mm includes its ostium "
                     "(grey band in the chart)"
                     + ("; **the lesion overlaps it: check the lesion ends**" if inside else "")
                     + in_it(b["start_mm"], b["end_mm"]) + ".")
    for view, other in (("a", "B"), ("b", "A")):
        for lo, hi in rec.centerline_3d.overlap_stretches_mm(view):
            lines.append(f"- {lo:.1f}–{hi:.1f} mm: another vessel overlaps view "
                         f"{view.upper()}; the diameter there uses view {other}'s width "
                         f"(yellow band in the chart){in_it(lo, hi)}.")
    return [""] + lines if lines else []
