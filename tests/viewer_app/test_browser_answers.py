"""Issue 46 in headless Chromium with real mouse events: the page never shows a wrong or
stale answer (landmarks paired in click order, results removed or marked out of date,
two patients refused), shows the inputs' warnings, gives the PDF and the SR, and lets a
mark be dragged and deleted. Screenshots go to test-artifacts/viewer/answers_*.png.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from browser_page import BOX_JS, CHROMIUM, Browser, demo_page, failed, wait_for

from recon.geometry import ViewGeometry
from viewer_app import ViewerApp

pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(not Path(CHROMIUM).is_file(), reason=f"no browser at {CHROMIUM}")]

MLD_TOLERANCE_MM = 0.15  # the bound on the demo's MLD against truth.json


def _truth_clicks(demo_case: dict[str, Path]) -> dict[str, object]:
    """The demo's truth: the MLD, and the side branch's start (the bifurcation) and end
    projected into A and B by the true geometries (pixels (col, row))."""
    truth = json.loads(Path(demo_case["a"]).with_name("truth.json").read_text())
    va = ViewGeometry.from_dict(truth["view_a"])
    vb = ViewGeometry.from_dict(truth["view_b_true"])
    branch = np.asarray(truth["vessels"][1]["X_world"], dtype=float)
    ends = branch[[0, -1]]
    return {"mld_mm": float(truth["stenosis"]["mld_mm"]), "a": va.project(ends),
            "b": vb.project(ends)}


def _press(b: Browser, name: str) -> None:
    b.page.get_by_role("button", name=name, exact=True).click()


def _reconstructed(b: Browser, app: ViewerApp, n_notes: int, timeout_s: float = 180) -> bool:
    """Press Reconstruct and wait for its end; whether it gave a result."""
    _press(b, "Reconstruct")
    wait_for(lambda: any(n[1].startswith("Reconstruct") for n in app.notifications[n_notes:]),
             timeout_s, "the reconstruction")
    return not any(n[1] == "Reconstruct failed" for n in app.notifications[n_notes:])


def test_landmarks_clicked_view_by_view_pair_in_order_on_the_page(
    demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    """Issue 46 item 1, the issue's order with the mouse: Clear marks; A proximal, B
    proximal, B distal, A distal; the bifurcation and the side branch's end in A, then
    their partners in B. The landmarks pair in click order and the MLD is the demo's
    truth within 0.15 mm (it was 1.97 mm against 1.44). Then the B partners clicked in
    the other order: the page says at once, in a warning, that the pair is doubtful."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    seeds = json.loads(Path(demo_case["seeds"]).read_text())
    seg = seeds["segments"][0]
    truth = _truth_clicks(demo_case)
    app = ViewerApp(str(demo_case["a"]), str(demo_case["b"]), str(demo_case["seeds"]),
                    port=0, autosave_path=tmp_path / "autosave.json")
    app.wait_ready()
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            b.open(app)
            _press(b, "Clear marks")
            wait_for(lambda: app.state.marks == [], 10, "Clear marks")
            steps = [("a", seg["a"][0]), ("b", seg["b"][0]), ("b", seg["b"][-1]),
                     ("a", seg["a"][-1]), ("a", truth["a"][0]), ("a", truth["a"][1]),
                     ("b", truth["b"][0]), ("b", truth["b"][1])]
            for view, (col, row) in steps:
                mark, notes = b.click(view, float(col), float(row))
                assert mark is not None and mark.view == view, notes
                assert not [n for n in notes if n[0] == "warning"], notes
            feats = app.state.to_seeds().features
            assert len(feats) == 2
            for f, k in zip(feats, (0, 1), strict=True):  # snapped: a few px at most
                assert np.hypot(*(np.asarray(f.a_px) - truth["a"][k])) < 6.0, f
                assert np.hypot(*(np.asarray(f.b_px) - truth["b"][k])) < 6.0, f
            b.shot("answers_1_landmarks_paired.png")
            n_notes = len(app.notifications)
            assert _reconstructed(b, app, n_notes), app.notifications[n_notes:]
            mld = app.reconstruction.measurements.mld_mm
            (artifacts_dir / "landmarks_in_order_mld.txt").write_text(
                f"MLD {mld:.3f} mm, truth {truth['mld_mm']:.3f} mm\n")
            assert abs(mld - truth["mld_mm"]) <= MLD_TOLERANCE_MM, (mld, truth["mld_mm"])
            assert not [n for n in app.notifications[n_notes:] if n[0] == "warning"], \
                app.notifications[n_notes:]
            b.page.wait_for_timeout(1200)
            b.shot("answers_2_landmarks_reconstructed.png")

            # The partners in B in the other order: the page warns at the second click.
            for _ in range(2):
                _press(b, "Undo")
            wait_for(lambda: len(app.state.waiting_landmarks("a")) == 2, 10, "two undos")
            _, notes = b.click("b", *map(float, truth["b"][1]))
            assert any(n[1] == "Check the landmark pair" for n in notes), notes
            b.page.get_by_text("Check the landmark pair").first.wait_for(state="visible",
                                                                         timeout=10_000)
            assert "⚠" in app.panels.marks.summary.content
            b.shot("answers_3_landmark_pair_doubted.png")
        finally:
            b.close()
            app.stop()


def test_no_earlier_result_is_shown_as_current_on_the_page(
    demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    """Issue 46 item 2 with the mouse: after Reconstruct, a mark clicked on B marks the
    results out of date (the page says so in the panel, over both images and beside the
    model) and Undo unmarks them; Clear marks leaves no model, trace, MLD, table or
    calibration; a failed Reconstruct after a good one leaves none either."""
    from dataclasses import replace

    from recon.io import load_seeds
    from recon.seeds import Seeds
    from viewer_app.results import NO_RECONSTRUCTION_TEXT

    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    app = ViewerApp(str(demo_case["a"]), str(demo_case["b"]), str(demo_case["seeds"]),
                    port=0, autosave_path=tmp_path / "autosave.json")
    app.wait_ready()
    model_nodes = "() => Object.keys(window.__viserMutable.nodeRefFromName)" \
        ".filter((n) => n.startsWith('/model') || n.endsWith('/out_of_date'))"
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            b.open(app)
            assert _reconstructed(b, app, len(app.notifications))
            b.page.wait_for_timeout(1000)
            b.choose("Mode", "Waypoint")
            wait_for(lambda: app.state.mode == "waypoint", 10, "the mode")
            mark, _ = b.click("b", 300.0, 200.0)
            assert mark is not None
            for name in ("/over_a/out_of_date", "/over_b/out_of_date", "/model/out_of_date"):
                b.page.wait_for_function(
                    f"() => '{name}' in window.__viserMutable.nodeRefFromName", timeout=10_000)
            b.page.get_by_text("these results are of earlier marks").first.wait_for(
                state="visible", timeout=10_000)
            b.shot("answers_4_results_out_of_date.png")
            _press(b, "Undo")
            wait_for(lambda: not app.panels.results.stale.visible, 10, "the undo")
            b.page.get_by_text("these results are of earlier marks").first.wait_for(
                state="hidden", timeout=10_000)
            assert app.server.scene.get_handle_by_name("/over_a/out_of_date") is None

            _press(b, "Clear marks")
            wait_for(lambda: app.reconstruction is None and app.state.marks == [], 10,
                     "Clear marks")
            b.reload()  # a page's lookup table keeps removed names: ask a fresh page
            assert b.page.evaluate(model_nodes) == []
            b.page.get_by_text(NO_RECONSTRUCTION_TEXT).first.wait_for(state="visible",
                                                                     timeout=10_000)
            b.page.get_by_text("Not calibrated").first.wait_for(state="visible",
                                                                timeout=10_000)
            b.shot("answers_5_cleared.png")

            # A good run, then one the tracing refuses: nothing of the first stays.
            seeds = load_seeds(demo_case["seeds"])
            app.load_seeds(str(demo_case["seeds"]))
            assert _reconstructed(b, app, len(app.notifications))
            seg = seeds.segments[0]
            a = seg.a_px
            bad = tmp_path / "out_of_order.json"
            bad.write_text(json.dumps(Seeds(segments=(replace(seg, a_px=(a[0], a[-1], a[1],
                                                                         a[2])),),
                                            features=seeds.features).to_dict()))
            app.access.add_read_root(tmp_path)
            assert app.load_seeds(str(bad))
            assert not _reconstructed(b, app, len(app.notifications))
            b.page.get_by_text("Reconstruct failed").first.wait_for(state="visible",
                                                                    timeout=10_000)
            assert app.reconstruction is None and app.model is None
            b.page.wait_for_timeout(1000)
            b.shot("answers_6_failed_run.png")
            b.reload()
            assert b.page.evaluate(model_nodes) == []
            assert not failed(app) or app.notifications[-1][1] == "Reconstruct failed"
        finally:
            b.close()
            app.stop()


def test_two_patients_wait_for_a_confirmation_the_page_shows(
    demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    """Issue 46 item 3 with the mouse: file B of another patient (its PatientID changed
    with pydicom). The page opens with a dialog saying that the files name different
    patients; closed, Reconstruct is refused in one line; the Marks folder's confirmation
    lets it run. The patient ID is nowhere on the page."""
    import pydicom

    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    ds = pydicom.dcmread(demo_case["b"])
    ds.PatientID = "OTHER-PATIENT-4711"
    other = tmp_path / "b_other_patient.dcm"
    ds.save_as(other)
    app = ViewerApp(str(demo_case["a"]), str(other), str(demo_case["seeds"]), port=0,
                    autosave_path=tmp_path / "autosave.json")
    app.wait_ready()
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            b.open(app)
            dialog = b.page.get_by_text("Files A and B name").first
            dialog.wait_for(state="visible", timeout=10_000)
            b.shot("answers_7_two_patients_dialog.png")
            assert "OTHER-PATIENT-4711" not in b.page.inner_text("body")
            b.page.get_by_role("button", name="Close (Reconstruct stays refused)").click()
            n_notes = len(app.notifications)
            assert not _reconstructed(b, app, n_notes)
            assert app.notifications[-1][2].startswith("files A and B name different patients")
            b.page.get_by_text("name different patients: open two views").first.wait_for(
                state="visible", timeout=10_000)
            # the guide line says what to do, not "press Reconstruct"
            b.page.get_by_text("Segment marked; before Reconstruct: files A and B name "
                               "different patients").first.wait_for(state="visible",
                                                                    timeout=10_000)
            assert "Segment ready" not in app.panels.marks.guide.content
            b.shot("answers_8_two_patients_refused.png")
            for _ in range(4):  # refused again and again: the notes do not pile up
                _press(b, "Reconstruct")
                b.page.wait_for_timeout(300)
            b.page.wait_for_timeout(600)
            toasts = b.page.locator(".mantine-Notification-root").count()
            assert toasts <= 3, toasts
            b.page.get_by_role("button", name="They are one patient's views").first.click()
            wait_for(lambda: app.patients_confirmed, 10, "the confirmation")
            assert _reconstructed(b, app, len(app.notifications))
            assert app.reconstruction is not None
            assert "OTHER-PATIENT-4711" not in b.page.inner_text("body")
        finally:
            b.close()
            app.stop()


def test_a_far_off_header_asks_for_a_landmark_pair_first_on_the_page(
    tmp_path: Path, artifacts_dir: Path
) -> None:
    """Issue 46's smaller point with the mouse, on IM7 / IM8 whose header puts B's marks
    about 40 px off their magenta lines: after both ends in A and B's proximal end, the
    guided order asks for a landmark pair before B's distal end and says to Calibrate;
    after Calibrate the guide line says only to Reconstruct."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    data = Path(__file__).resolve().parents[1] / "data"
    seeds = json.loads((data / "im7_im8_tree_seeds.json").read_text())
    seg, feat = seeds["segments"][0], seeds["features"][0]
    app = ViewerApp(str(data / "IM7.dcm"), str(data / "IM8.dcm"), None, port=0,
                    autosave_path=tmp_path / "autosave.json")
    app.wait_ready()
    guide = app.panels.marks.guide
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            b.open(app)
            for view, (col, row) in (("a", seg["a"][0]), ("a", seg["a"][-1]),
                                     ("b", seg["b"][0])):
                mark, notes = b.click(view, float(col), float(row))
                assert mark is not None, notes
            assert app.state.header_error_px() > 20.0
            assert guide.content.startswith("Next click in **A**: landmark · in **B**: landmark.")
            assert "Click a landmark pair" in guide.content
            b.page.get_by_text("View B's header geometry is off").first.wait_for(
                state="visible", timeout=10_000)
            b.shot("answers_15_header_far_off.png")
            for view, (col, row) in (("a", feat["a"]), ("b", feat["b"])):
                mark, notes = b.click(view, float(col), float(row))
                assert mark is not None and mark.kind == "feature", notes
            mark, notes = b.click("b", *map(float, seg["b"][-1]))
            assert mark is not None and mark.kind == "distal", notes
            assert "press **Calibrate**, then **Reconstruct**" in guide.content
            _press(b, "Calibrate (PALM)")
            wait_for(lambda: app.calibration is not None or failed(app), 120, "calibration")
            assert app.calibration is not None, app.notifications[-3:]
            wait_for(lambda: "✔ Segment ready: press **Reconstruct**." in guide.content, 10,
                     "the guide line after Calibrate")
            assert "header" not in guide.content
            b.page.wait_for_timeout(800)
            b.shot("answers_16_header_calibrated.png")
        finally:
            b.close()
            app.stop()


def test_the_inputs_warnings_are_on_the_page(
    demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    """Issue 46 item 6: file B stored display-processed (its PixelIntensityRelationship
    set to DISP with pydicom): the case table says so as soon as the pair is open, and
    the results say it above their table after Reconstruct (it was in report.json only)."""
    import pydicom

    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    ds = pydicom.dcmread(demo_case["b"])
    ds.PixelIntensityRelationship = "DISP"
    shown_b = tmp_path / "b_display.dcm"
    ds.save_as(shown_b)
    app = ViewerApp(str(demo_case["a"]), str(shown_b), str(demo_case["seeds"]), port=0,
                    autosave_path=tmp_path / "autosave.json")
    app.wait_ready()
    line = "view B: display-processed image (PixelIntensityRelationship DISP)"
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            b.open(app)
            case = b.page.get_by_text(line).first
            case.scroll_into_view_if_needed()
            case.wait_for(state="visible", timeout=10_000)
            b.shot("answers_9_input_warning_case.png")
            assert _reconstructed(b, app, len(app.notifications))
            assert any(line in w for w in app.reconstruction.warnings)
            assert line in app.panels.results.warnings.content
            heading = b.page.get_by_text("Read with these figures:").first
            heading.scroll_into_view_if_needed()
            heading.wait_for(state="visible", timeout=10_000)
            b.shot("answers_10_input_warning_results.png")
        finally:
            b.close()
            app.stop()


def _download(b: Browser, button: str, to: Path) -> Path:
    with b.page.expect_download(timeout=120_000) as info:
        b.page.get_by_role("button", name=button, exact=True).click()
    info.value.save_as(to)
    return to


def test_the_report_pdf_and_sr_of_the_whole_tree_download_from_the_page(
    tmp_path: Path, artifacts_dir: Path
) -> None:
    """Issue 46 item 7 with the mouse: the demo tree (LAD with its side branch D1)
    reconstructed, then "Download report (PDF)" and "Download DICOM SR" pressed; the PDF
    (read back with pypdf) and the SR (highdicom and dcmtk's dsrdump) hold every
    segment with its 95 % intervals, report.json's figures."""
    import shutil
    import subprocess
    from dataclasses import replace

    import highdicom as hd
    import pypdf

    from recon.io import demo_paths, save_seeds
    from recon.seeds import Seeds
    from recon.synth import make_phantom
    from recon.synth.tree_case import tree_seeds

    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    seeds, _, _ = tree_seeds(np.random.default_rng(1), make_phantom("static", 7, render=False))
    main, side = seeds.segments
    named = Seeds(segments=(replace(main, name="LAD"), replace(side, name="D1", parent="LAD")),
                  features=seeds.features)
    save_seeds(named, tmp_path / "tree.json")
    demo = demo_paths()
    app = ViewerApp(str(demo["a"]), str(demo["b"]), str(tmp_path / "tree.json"), port=0,
                    autosave_path=tmp_path / "autosave.json")
    app.wait_ready()
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            b.open(app)
            # before any Reconstruct the page says what to do first
            b.page.get_by_role("button", name="Download report (PDF)").click()
            b.page.get_by_text("reconstruct first").first.wait_for(state="visible",
                                                                   timeout=10_000)
            assert _reconstructed(b, app, len(app.notifications))
            rec = app.reconstruction
            assert len(getattr(rec, "branches", ())) == 2, app.notifications[-3:]
            report = rec.report()
            b.page.get_by_role("button", name="Download DICOM SR").scroll_into_view_if_needed()
            b.shot("answers_11_report_buttons.png")
            pdf = _download(b, "Download report (PDF)", tmp_path / "report.pdf")
            sr = _download(b, "Download DICOM SR", tmp_path / "measurements-sr.dcm")
        finally:
            b.close()
            app.stop()
    text = "\n".join(page.extract_text() for page in pypdf.PdfReader(pdf).pages)
    (artifacts_dir / "answers_report.txt").write_text(text)
    for branch in report["branches"]:
        name, m = branch["inputs"]["segment"], branch["measurements"]
        assert name in text
        lo, hi = branch["measurements_ci95"]["mld_mm"]
        assert f"{m['mld_mm']:.2f}" in text and f"{lo:.2f}" in text and f"{hi:.2f}" in text
    groups = hd.sr.srread(sr).content.get_image_measurement_groups()
    names = [g.tracking_identifier for g in groups]
    assert {"LAD", "D1"} <= set(names), names
    by_name = {g.tracking_identifier: g for g in groups}
    for branch in report["branches"]:  # report.json's figures to the digit
        name = branch["inputs"]["segment"]
        mld = [m for m in by_name[name].get_measurements() if m.name.value == "397413000"]
        assert mld and mld[0].value == pytest.approx(branch["measurements"]["mld_mm"],
                                                     rel=1e-9)
    if shutil.which("dsrdump"):
        proc = subprocess.run(["dsrdump", "-Ee", str(sr)], capture_output=True, text=True,
                              timeout=60)
        assert proc.returncode == 0 and "E:" not in proc.stderr, proc.stderr
        assert '"LAD"' in proc.stdout and '"D1"' in proc.stdout


def _drag(b: Browser, start: tuple[float, float], end: tuple[float, float]) -> None:
    """A left drag with the mouse between two screen points, in small steps."""
    b.page.mouse.move(*start)
    b.page.mouse.down()
    b.page.mouse.move(*end, steps=15)
    b.page.mouse.up()


def test_a_mark_is_dragged_and_deleted_and_the_camera_stays_on_the_angiograms(
    demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    """Issue 46 item 8 with the mouse, on both images: a mark dragged along its vessel
    moves there (snapped; the same mark, no new one), Undo puts it back; a drag on an
    image away from the marks moves nothing and never turns the camera; the selected
    mark is deleted with "Delete selected mark" and Undo brings it back; a drag on the
    model still turns the page to the model."""
    from viewer_app import scene

    with demo_page(demo_case, tmp_path, artifacts_dir) as (app, b):
        client = next(iter(app.server.get_clients().values()))
        n_marks = len(app.state.marks)
        for view in ("a", "b"):
            wp = [m for m in app.state.marks if m.view == view and m.kind == "waypoint"]
            mark, target = wp[0], np.asarray(wp[1].point_px)
            # half-way to the next waypoint along the vessel
            goal = (np.asarray(mark.point_px) + target) / 2
            _drag(b, b.screen_xy(view, *mark.point_px), b.screen_xy(view, *goal))
            wait_for(lambda m=mark: app.state.mark_by_id(m.id).point_px != m.point_px,
                     10, f"the {view.upper()} mark to move")
            wait_for(lambda: app._drag is None, 10, "the drag to end")
            moved = app.state.mark_by_id(mark.id)
            assert np.hypot(*(np.asarray(moved.point_px) - goal)) < 8.0, (moved, goal)
            assert moved.snap_distance_px is not None  # snapped where it was let go
            b.page.wait_for_timeout(500)
            assert len(app.state.marks) == n_marks  # the drag placed no new mark
            assert app.layout == "Angiograms" and scene.camera_rotated_deg(client) < 0.5
            b.shot(f"answers_12_mark_dragged_{view}.png")
            _press(b, "Undo")
            wait_for(lambda m=mark: app.state.mark_by_id(m.id).point_px == m.point_px,
                     10, "the undo of the drag")
            # a drag on the image away from every mark: nothing moves, nor the camera
            before = list(app.state.marks)
            _drag(b, b.screen_xy(view, 60.0, 60.0), b.screen_xy(view, 200.0, 120.0))
            b.page.wait_for_timeout(800)
            assert app.state.marks == before
            assert app.layout == "Angiograms" and scene.camera_rotated_deg(client) < 0.5
        # delete the selected mark, then undo
        mark = next(m for m in app.state.marks if m.view == "b" and m.kind == "waypoint")
        b.choose("Selected mark", f"B {app.state.label(mark)} #{mark.id}")
        wait_for(lambda: app.state.selected_id == mark.id, 10, "the selection")
        _press(b, "Delete selected mark")
        wait_for(lambda: app.state.mark_by_id(mark.id) is None, 10, "the deletion")
        b.shot("answers_13_mark_deleted.png")
        _press(b, "Undo")
        wait_for(lambda: app.state.mark_by_id(mark.id) == mark, 10, "the undo")
        # the model still turns with a drag on it
        assert _reconstructed(b, app, len(app.notifications))
        b.page.wait_for_timeout(1500)
        box = b.page.evaluate(BOX_JS, "/model/mesh")
        cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
        _drag(b, (cx, cy), (cx + 160, cy + 40))
        wait_for(lambda: app.layout == "3D model", 10, "the page to turn to the model")
        b.page.wait_for_timeout(800)
        b.shot("answers_14_model_rotated.png")
