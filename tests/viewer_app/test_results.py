"""The panels' texts (viewer_app.results) from small stand-ins of the results."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from viewer_app.results import (
    NO_RECONSTRUCTION_TEXT,
    NOT_CALIBRATED_TEXT,
    angle_text,
    bifurcations_markdown,
    calibration_markdown,
    fmt,
    info_markdown,
    lesion_measurements,
    lesions_lines,
    marks_markdown,
    results_markdown,
    warnings_markdown,
)


def test_angles_read_as_a_clinician_says_them() -> None:
    assert angle_text(-29.3, 25.5) == "RAO 29.3° / CRA 25.5°"
    assert angle_text(30.7, -3.0) == "LAO 30.7° / CAU 3.0°"
    assert angle_text(0.0, 0.0) == "LAO 0.0° / CRA 0.0°"


def test_table_cells() -> None:
    assert fmt(1.23456) == "1.23"
    assert fmt(np.float32(0.5)) == "0.5"
    assert fmt(123456.7) == "123457"
    assert fmt([1.0, 2.5]) == "1, 2.5"
    assert fmt((3, "x")) == "3, x"
    assert fmt(7) == "7" and fmt(None) == "None"


def _angio(alpha: float, beta: float, frame: int, n_frames: int) -> SimpleNamespace:
    from recon.geometry import ViewGeometry

    geometry = ViewGeometry(alpha_deg=alpha, beta_deg=beta, sid_mm=976.0, sod_mm=720.4,
                            pixel_spacing_mm=(0.3, 0.3), rows=512, cols=480)
    return SimpleNamespace(geometry=geometry, frame_index=frame, n_frames=n_frames)


def test_info_table() -> None:
    text = info_markdown(_angio(-29.3, 25.5, 0, 1), _angio(30.7, 23.6, 3, 9), "a.dcm", "b.dcm")
    assert text == "\n".join([
        "| | A | B |",
        "| --- | --- | --- |",
        "| file | a.dcm | b.dcm |",
        "| angles | RAO 29.3° / CRA 25.5° | LAO 30.7° / CRA 23.6° |",
        "| SID / SOD (mm) | 976 / 720 | 976 / 720 |",
        "| size | 480×512 | 480×512 |",
        "| frame | 1/1 | 4/9 |",
        "\nViews 54° apart.",
    ])


def test_info_warns_when_the_views_are_too_similar() -> None:
    text = info_markdown(_angio(30.0, 0.0, 0, 1), _angio(10.0, 5.0, 0, 1), "a.dcm", "b.dcm")
    assert "Views 21° apart." in text
    assert "Views too similar" in text and "refuse" in text
    far = info_markdown(_angio(-30.0, 0.0, 0, 1), _angio(30.0, 0.0, 0, 1), "a.dcm", "b.dcm")
    assert "too similar" not in far


def test_the_case_table_says_what_the_files_make_less_certain() -> None:
    """Issue 46 item 6: an 8-bit, display-processed file is named in the case table as
    soon as the pair is open (it was in report.json only)."""
    b = _angio(30.7, 23.6, 0, 1)
    b.info = {"bits_stored": 8, "pixel_intensity_relationship": "DISP"}
    text = info_markdown(_angio(-29.3, 25.5, 0, 1), b, "a.dcm", "b.dcm")
    assert ("⚠ view B: 8-bit, display-processed image (PixelIntensityRelationship DISP); "
            "its radii are less certain") in text
    assert "view A" not in text


def test_the_results_warnings_and_a_doubtful_calibration_head_the_results() -> None:
    calibration = SimpleNamespace(warnings=(
        "underdetermined: 3 features constrain fewer than the 5 observable pose parameters",
        "feature 3 is still 14.5 px off after calibration; check the click",
        "implausible correction: 6.7 deg and 9.7 mm (header errors are expected below ...)"))
    result = SimpleNamespace(warnings=("view B: 8-bit image; its radii are less certain",),
                             calibration=calibration)
    text = warnings_markdown(result)
    assert text.splitlines()[0] == "**Read with these figures:**"
    assert "- ⚠ view B: 8-bit image; its radii are less certain" in text
    assert "- ⚠ feature 3 is still 14.5 px off after calibration; check the click" in text
    assert "implausible correction" in text and "underdetermined" not in text
    assert warnings_markdown(SimpleNamespace(warnings=(), calibration=None)) == ""


def test_marks_summary() -> None:
    seeds = SimpleNamespace(segments=[object()], features=[object(), object()])
    state = SimpleNamespace(
        marks=[object()] * 5, to_seeds=lambda: seeds, last_message="too far",
        missing=lambda: [f"missing {i}" for i in range(8)], segment_names=["Segment 1"],
    )
    text = marks_markdown(state, 1.234, "/tmp/auto.json")
    lines = text.splitlines()
    assert lines[0] == "**5 marks**: 1 complete segment(s), 2 feature pair(s)."
    assert lines[1:7] == [f"- missing {i}" for i in range(6)]  # at most six
    assert lines[7] == "- ⚠ too far"
    assert "Last click → epipolar line: 1.2 ms (server)." in text
    assert text.endswith("\nAutosave: `/tmp/auto.json`")
    state.last_message = None
    quiet = marks_markdown(state, float("nan"), "/tmp/auto.json")
    assert "⚠" not in quiet and "Last click" not in quiet


def test_calibration_table() -> None:
    res = SimpleNamespace(
        rotvec=np.radians([0.0, 0.0, 1.5]), t_mm=np.array([3.0, 4.0, 0.0]),
        error_before_px=2.744, error_after_px=0.261, error_before_mm=1.07, error_after_mm=0.1,
        iterations=5, elapsed_ms=7.4,
        warnings=("ill-conditioned", "underdetermined: 3 features constrain fewer than the 5"),
    )
    assert calibration_markdown(res) == "\n".join([
        "| | before | after |",
        "| --- | --- | --- |",
        "| error (px) | 2.74 | 0.26 |",
        "| error (mm) | 1.07 | 0.10 |",
        "",
        "Pose correction of B: **1.50°** rotation, **5.00 mm** translation "
        "(3.00, 4.00, 0.00 mm); 5 iterations, 7 ms.",
        "- ⚠ ill-conditioned",
        "- ℹ 3 correspondences (the 2 segment ends + 1 landmark pair(s)): with 5 or more "
        "the images alone fix view B's pose; with fewer the header's expected accuracy fills "
        "in. Add 2 landmark pair(s) (branch points) to firm it up.",
    ])
    assert "Not calibrated" in NOT_CALIBRATED_TEXT and NO_RECONSTRUCTION_TEXT


def test_results_tables() -> None:
    stretches = {"a": [(1.0, 2.5)], "b": []}
    rec = SimpleNamespace(
        measurements=SimpleNamespace(to_dict=lambda: {"mld_mm": 1.234, "lesion": None}),
        centerline_3d=SimpleNamespace(overlap_stretches_mm=lambda view: stretches[view]),
        metrics={"a": {"x": 0.5, "y": 2.0}, "b": {"x": 0.25, "z": 1.0}, "rmse_mm": 0.123},
        timings_ms={"trace": 12.345, "total": 20000.0},
    )
    assert results_markdown(rec) == "\n".join([
        "| measurement | value |",
        "| --- | --- |",
        "| mld_mm | 1.23 |",
        "| lesion | None |",
        "| view A overlapped: radius from view B | 1.0-2.5 mm |",
        "",
        "| Table 3 | view A | view B |",
        "| --- | --- | --- |",
        "| x | 0.5 | 0.25 |",
        "",
        "| Table 3 (both views) | value |",
        "| --- | --- |",
        "| rmse_mm | 0.123 |",
        "",
        "| stage | ms |",
        "| --- | --- |",
        "| trace | 12.3 |",
        "| total | 20000 |",
    ])


def test_lesion_ends_set_by_hand() -> None:
    s = np.linspace(0.0, 50.0, 501)
    d = 3.0 - 0.02 * s - 1.5 * np.exp(-(((s - 25.0) / 3.0) ** 2))  # tapering, a lesion at 25
    prof = SimpleNamespace(s_mm=s, diameter_smooth_mm=d)
    v = lesion_measurements(prof, 15.0, 35.0)
    assert v["lesion_length_mm"] == 20.0 and v["mld_s_mm"] == pytest.approx(25.0, abs=0.2)
    assert v["mld_mm"] == pytest.approx(float(d.min()))
    assert v["proximal_reference_mm"] == pytest.approx(3.0 - 0.3, abs=1e-3)
    assert v["distal_reference_mm"] == pytest.approx(3.0 - 0.7, abs=1e-3)
    ref = 3.0 - 0.02 * 25.0  # the straight reference at the MLD: the healthy taper
    assert v["reference_diameter_mm"] == pytest.approx(ref, abs=5e-3)
    assert v["diameter_stenosis_pct"] == pytest.approx(100 * 1.5 / ref, abs=0.5)
    assert lesion_measurements(prof, 35.0, 15.0) == v  # the ends in either order
    assert (v["proximal_reference_s_mm"], v["distal_reference_s_mm"]) == (15.0, 35.0)
    # Reference sites moved out of the lesion's shoulders: the reference at the MLD is
    # read between them (2D QCA's user-defined reference), the MLD is not.
    w = lesion_measurements(prof, 15.0, 35.0, (5.0, 45.0))
    assert w["mld_mm"] == v["mld_mm"] and w["lesion_length_mm"] == 20.0
    assert w["proximal_reference_mm"] == pytest.approx(3.0 - 0.1, abs=1e-3)
    assert w["distal_reference_mm"] == pytest.approx(3.0 - 0.9, abs=1e-3)
    assert w["reference_diameter_mm"] == pytest.approx(ref, abs=5e-3)
    assert lesion_measurements(prof, 15.0, 35.0, (45.0, 5.0)) == w


def test_diameter_colour_scale() -> None:
    from viewer_app.scene import diameter_colors

    rgb = diameter_colors(np.array([1.0, 1.5, 3.0, 4.0]), 3.0)
    assert rgb.dtype == np.uint8 and rgb.shape == (4, 3)
    assert tuple(rgb[0]) == (220, 30, 30)  # half the reference or less: red
    assert tuple(rgb[2]) == tuple(rgb[3]) == (40, 180, 70)  # at the reference: green
    # Against a tapering reference: a healthy distal vessel (2 mm where the reference
    # is 2 mm) is green, a 2 mm narrowing where it is 4 mm is red-orange.
    taper = diameter_colors(np.array([4.0, 2.0, 2.0]), np.array([4.0, 4.0, 2.0]))
    assert tuple(taper[0]) == tuple(taper[2]) == (40, 180, 70)
    assert tuple(taper[1]) == (220, 30, 30)


def test_results_show_the_95_pct_interval_beside_the_value() -> None:
    rec = SimpleNamespace(
        measurements=SimpleNamespace(to_dict=lambda: {"mld_mm": 1.48, "has_lesion": True}),
        centerline_3d=SimpleNamespace(overlap_stretches_mm=lambda view: []),
        metrics={}, timings_ms={},
        intervals=SimpleNamespace(ci95={"mld_mm": (1.39, 1.57)}),
    )
    lines = results_markdown(rec).splitlines()
    assert "| mld_mm | 1.48 (1.39-1.57) |" in lines
    assert "| has_lesion | True |" in lines


def test_the_bifurcation_table_says_when_a_branch_origin_is_doubtful() -> None:
    from dataclasses import replace

    from recon.lumen.bifurcation import bifurcation_qca

    s = np.arange(0.0, 60.0, 0.1)
    parent = np.column_stack([s, 0 * s, 0 * s])
    t = np.deg2rad(60.0)
    branch = np.column_stack([30.0 + s[:300] * np.cos(t), s[:300] * np.sin(t), 0 * s[:300]])
    d = (s, np.full(len(s), 3.0), np.full(len(s), 3.0))
    b = (s[:300], np.full(300, 2.0), np.full(300, 2.0))
    fine = bifurcation_qca("LAD/D1", "LAD", "D1", parent, d, branch, b, 0.0)
    assert fine.origin_warning is None
    doubt = replace(fine, origin_warning="LAD/D1: in view B the trace of D1 runs 80 px along LAD")
    assert "⚠" not in bifurcations_markdown(SimpleNamespace(bifurcations=(fine,)))
    table = bifurcations_markdown(SimpleNamespace(bifurcations=(fine, doubt)))
    assert "- ⚠ LAD/D1: in view B the trace of D1 runs 80 px along LAD" in table
    assert table.count("⚠") == 1


def test_every_lesion_is_listed_with_its_intervals() -> None:
    """Issue 46 item 5 on the page: every narrowing that passes the lesion criterion,
    numbered, with MLD, % DS and length and their 95 % intervals (recon.lumen.lesions)."""
    def lesion(number: int, s_mm: float, mld: float, ds: float) -> SimpleNamespace:
        n = SimpleNamespace(mld_s_mm=s_mm, mld_mm=mld, diameter_stenosis_pct=ds, length_mm=6.0)
        return SimpleNamespace(number=number, narrowing=n,
                               ci95={"mld_mm": (mld - 0.2, mld + 0.2),
                                     "diameter_stenosis_pct": (ds - 8, ds + 8)})

    report = SimpleNamespace(lesions=(lesion(1, 20.0, 1.6, 45.0), lesion(2, 48.0, 1.4, 52.0)),
                             primary=1, summary=lambda: "2 lesions; no single most severe")
    lines = lesions_lines(SimpleNamespace(lesions=report))
    assert lines[1] == "**Lesions**: 2 lesions; no single most severe."
    assert "| 1 | 20.0 mm | 1.60 mm (1.40–1.80) | 45 % (37–53) | 6.0 mm |" in lines
    assert "| 2 (table above) | 48.0 mm | 1.40 mm (1.20–1.60) | 52 % (44–60) | 6.0 mm |" in lines
    assert lesions_lines(SimpleNamespace()) == []
