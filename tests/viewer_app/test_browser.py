"""The viewer in headless Chromium with real mouse events: clicks land on the image they
were made on in every order, a new pair shows no old marks, and a guided session from an
empty page to a mesh (calibration figures, camera layouts, reload, download).

Few fat tests (the first WebGL render costs seconds on a small machine).
Screenshots go to test-artifacts/viewer/. Needs /usr/bin/chromium and the
``playwright`` package (no ``playwright install``: the system Chromium is used).
"""

from __future__ import annotations

import json
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh
from browser_page import (  # tests/viewer_app/browser_page.py
    CANVAS_JS,
    CHROMIUM,
    MARK_LABELS_JS,
    Browser,
    failed,
    screen_box,
    wait_for,
)

from recon.io import load_seeds
from viewer_app import ViewerApp, scene
from viewer_app.state import MODE_LABELS

pytestmark = pytest.mark.browser


def _assert_lands(b: Browser, view: str, col: float, row: float, where: str) -> None:
    mark, notes = b.click(view, col, row)
    assert mark is not None, f"{where}: click on {view.upper()} ({col:.0f}, {row:.0f}) " \
        f"refused: {notes}"
    assert mark.view == view, f"{where}: click on {view.upper()} landed on {mark.view.upper()}"
    assert np.hypot(mark.raw_px[0] - col, mark.raw_px[1] - row) < 1.5, (
        f"{where}: click on {view.upper()} ({col:.1f}, {row:.1f}) arrived at {mark.raw_px}")


GRID = [(c, r) for c in np.linspace(40, 470, 5) for r in np.linspace(60, 470, 3)]


@pytest.mark.skipif(not Path(CHROMIUM).is_file(), reason=f"no browser at {CHROMIUM}")
def test_every_click_lands_on_the_image_it_was_made_on(
    demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    """The issue-16 defect: once B held a mark, clicks on A were caught by it (and vice
    versa). Every order: A then B, B then A, interleaved, after a reload, after a server
    restart; and the Mode dropdown shows the restored mode after the restart."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    autosave = tmp_path / "autosave.json"
    files = (str(demo_case["a"]), str(demo_case["b"]))

    def start() -> ViewerApp:
        viewer = ViewerApp(*files, None, port=0, autosave_path=autosave)
        viewer.wait_ready()
        return viewer

    app = start()
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            b.open(app)
            b.shot("clicks_0_empty.png")
            # The case: one mark in B at (128, 383), then clicks all over A.
            _assert_lands(b, "b", 128, 383, "B first")
            app.set_mode("waypoint")  # any number of marks per view
            for col, row in GRID:
                _assert_lands(b, "a", col, row, "A after a mark in B")
            # ... and an A mark at (480, 400), then clicks all over B.
            _assert_lands(b, "a", 480, 400, "A")
            for col, row in GRID:
                _assert_lands(b, "b", col, row, "B after marks in A")
            b.shot("clicks_1_a_then_b.png")
            for (ca, ra), (cb, rb) in zip(GRID[::2], GRID[1::2], strict=False):
                _assert_lands(b, "a", ca, ra, "interleaved")
                _assert_lands(b, "b", cb, rb, "interleaved")
            b.reload()
            for col, row in GRID[:4]:
                _assert_lands(b, "b", col, row, "after a reload")
                _assert_lands(b, "a", row, col, "after a reload")
            b.shot("clicks_2_after_reload.png")

            # A server restart: the autosave restores the marks and the mode, and the
            # page's Mode dropdown says so (it said "Segment proximal end" before).
            app.set_mode("feature")
            _assert_lands(b, "a", 300, 300, "before the restart")
            n_marks = len(app.state.marks)
            app.stop()
            app = start()
            assert len(app.state.marks) == n_marks and app.state.mode == "feature"
            b.open(app)
            assert b.dropdown_value("Mode") == MODE_LABELS["feature"]
            mark, _ = b.click("b", 320, 310)
            assert mark is not None and mark.kind == "feature" and mark.view == "b"
            for col, row in GRID[-4:]:
                _assert_lands(b, "a", col, row, "after a restart")
                _assert_lands(b, "b", row, col, "after a restart")
            # The mode picked in the page is the one used.
            b.choose("Mode", MODE_LABELS["waypoint"])
            wait_for(lambda: app.state.mode == "waypoint", 10, "the mode to reach the server")
            mark, _ = b.click("a", 250, 250)
            assert mark is not None and mark.kind == "waypoint"
            b.shot("clicks_3_after_restart.png")
        finally:
            b.close()
            app.stop()


@pytest.mark.skipif(not Path(CHROMIUM).is_file(), reason=f"no browser at {CHROMIUM}")
def test_a_new_pair_shows_no_old_marks(
    demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    """Opening another pair used to leave the old mark labels drawn (panel: 0 marks)."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    app = ViewerApp(str(demo_case["a"]), str(demo_case["b"]), str(demo_case["seeds"]),
                    port=0, autosave_path=tmp_path / "autosave.json")
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            b.open(app)
            assert len(b.page.evaluate(MARK_LABELS_JS)) == len(app.state.marks) > 0
            other = tmp_path / "other"
            other.mkdir()
            pa, pb = other / "a.dcm", other / "b.dcm"  # the same images under other names
            shutil.copy(demo_case["b"], pa)
            shutil.copy(demo_case["a"], pb)
            app.access.add_read_root(other)  # as if the server had been started on that folder
            assert app.open_pair(str(pa), str(pb))
            assert app.state.marks == []
            b.page.wait_for_timeout(1500)
            b.shot("new_pair_no_old_marks.png")
            # The scene the server sends to a page holds no label of the old marks (a
            # live page keeps stale names in its lookup table, so reload to ask).
            b.reload()
            assert b.page.evaluate(MARK_LABELS_JS) == []
            # Views too similar: the page says so as soon as the pair is open.
            from recon.io.overrides import GeometryOverrides

            ga = app.views["a"].angio.geometry
            assert app.open_pair(str(pa), str(pb), overrides_b=GeometryOverrides(
                alpha_deg=ga.alpha_deg + 10.0, beta_deg=ga.beta_deg))
            warning = b.page.get_by_text("Views too similar").first
            warning.wait_for(state="visible", timeout=10_000)
            b.shot("new_pair_views_too_similar.png")
        finally:
            b.close()
            app.stop()


@pytest.mark.skipif(not Path(CHROMIUM).is_file(), reason=f"no browser at {CHROMIUM}")
def test_a_refused_trace_is_ringed_on_the_page(
    demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    """Issue 13: the page shows the refusal's one line and a ring where it asks for a
    waypoint (view A's distal end clicked second: the trace doubles back there)."""
    from dataclasses import replace

    from recon.seeds import Seeds

    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    app = ViewerApp(str(demo_case["a"]), str(demo_case["b"]), str(demo_case["seeds"]),
                    port=0, autosave_path=tmp_path / "autosave.json")
    seeds = app.seeds()
    seg = seeds.segments[0]
    a = seg.a_px
    app.state.load_seeds(Seeds(segments=(replace(seg, a_px=(a[0], a[-1], a[1], a[2])),),
                               features=seeds.features))
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            b.open(app)
            assert app.reconstruct() is None
            b.page.get_by_text("Reconstruct failed").first.wait_for(state="visible",
                                                                    timeout=20_000)
            b.page.wait_for_function(
                "() => '/over_a/refusal' in window.__viserMutable.nodeRefFromName",
                timeout=10_000)
            b.shot("refused_trace_ringed.png")
        finally:
            b.close()
            app.stop()


@pytest.mark.skipif(not Path(CHROMIUM).is_file(), reason=f"no browser at {CHROMIUM}")
def test_guided_session_from_an_empty_page_to_a_mesh(
    demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    """From the demo page with no marks to a mesh in at most 8 clicks on the images plus
    button presses; Calibrate and Reconstruct agree; the camera never tilts the
    angiograms; a reload shows the model whole; a download reaches the browser."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    seeds = load_seeds(demo_case["seeds"])
    seg, feat = seeds.segments[0], seeds.features[0]
    app = ViewerApp(str(demo_case["a"]), str(demo_case["b"]), None, port=0,
                    autosave_path=tmp_path / "autosave.json")
    app.wait_ready()
    image_clicks = 0
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            t0 = time.perf_counter()
            b.open(app)
            (artifacts_dir / "page_ready_s.txt").write_text(f"{time.perf_counter() - t0:.2f}\n")
            assert app.state.marks == [] and b.dropdown_value("Mode") == MODE_LABELS["guided"]
            b.shot("guided_0_empty.png")
            # The guided order: both ends in A, both in B, then one landmark pair; the mode
            # advances by itself (no mode change between the clicks).
            steps = [("a", seg.a_px[0], "proximal"), ("a", seg.a_px[-1], "distal"),
                     ("b", seg.b_px[0], "proximal"), ("b", seg.b_px[-1], "distal"),
                     ("a", feat.a_px, "feature"), ("b", feat.b_px, "feature")]
            for i, (view, (col, row), kind) in enumerate(steps, start=1):
                mark, notes = b.click(view, col, row)
                image_clicks += 1
                assert mark is not None and (mark.view, mark.kind) == (view, kind), notes
                if i in (1, 2, 5):  # the next click in the other view has a guide line
                    nxt = steps[i] if i == 5 else steps[2 if i == 2 else 2]
                    epi = app.epipolar_segments["b"]
                    assert epi is not None
                    if i == 2:  # the line drawn in B passes the proximal end B is to get
                        d, w = epi[1] - epi[0], np.asarray(nxt[1]) - epi[0]
                        assert abs(d[0] * w[1] - d[1] * w[0]) / np.linalg.norm(d) < 15.0
                b.shot(f"guided_{i}_{view}_{kind}.png")
            assert b.dropdown_value("Mode") == MODE_LABELS["guided"]
            assert "Segment ready" in app.panels.marks.guide.content

            # Calibrate, then Reconstruct: the same figures for the same marks.
            b.page.get_by_role("button", name="Calibrate (PALM)").click()
            wait_for(lambda: app.calibration is not None or failed(app), 120, "calibration")
            assert app.calibration is not None, app.notifications[-3:]
            def errors() -> list[str]:  # the before / after rows of the calibration table
                return [r for r in app.panels.calibrate.markdown.content.splitlines()
                        if r.startswith("| error")]

            calibrated = errors()
            assert len(calibrated) == 2
            b.page.get_by_role("button", name="Reconstruct", exact=True).click()
            wait_for(lambda: app.reconstruction is not None or failed(app), 180, "reconstruction")
            rec = app.reconstruction
            assert rec is not None, app.notifications[-3:]
            assert errors() == calibrated, (calibrated, errors())
            assert image_clicks <= 8
            mesh = trimesh.Trimesh(rec.surface.mesh.vertices, rec.surface.mesh.faces)
            assert mesh.is_watertight and mesh.volume > 0
            (artifacts_dir / "clicks_to_mesh.txt").write_text(
                f"{image_clicks} clicks on the images + 2 button presses (Calibrate, "
                f"Reconstruct; Calibrate is optional)\n")
            b.page.wait_for_timeout(1500)
            b.shot("guided_7_reconstructed.png")
            assert app.layout == "Angiograms + 3D"

            # A drag on an image turns nothing (issue 46: it hid the angiograms); a drag
            # on the model rotates it: the page turns to the model alone, and
            # "Angiograms + 3D" brings the straight view back.
            cx, cy = b.screen_xy("a", 60, 60)
            b.page.mouse.move(cx, cy)
            b.page.mouse.down()
            b.page.mouse.move(cx + 160, cy + 40, steps=12)
            b.page.mouse.up()
            b.page.wait_for_timeout(800)
            assert app.layout == "Angiograms + 3D" and app.views["a"].nodes.image.visible
            box = screen_box(b, "/model/mesh")
            cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
            b.page.mouse.move(cx, cy)
            b.page.mouse.down()
            b.page.mouse.move(cx + 160, cy + 40, steps=12)
            b.page.mouse.up()
            wait_for(lambda: app.layout == "3D model", 10, "the page to turn to the 3D model")
            assert not app.views["a"].nodes.image.visible
            b.page.wait_for_timeout(800)
            b.shot("guided_8_model_rotated.png")
            b.choose("Show", "Angiograms + 3D")
            wait_for(lambda: app.layout == "Angiograms + 3D", 10, "the layout")
            b.page.wait_for_timeout(800)
            client = next(iter(app.server.get_clients().values()))
            wait_for(lambda: scene.camera_rotated_deg(client) < 0.5, 10, "a straight camera")
            assert app.views["a"].nodes.image.visible

            # After a reload the model is whole on the screen.
            b.reload()
            box = screen_box(b, "/model/mesh")
            canvas = b.page.evaluate(CANVAS_JS)
            assert box[0] >= 0 and box[1] >= 0 and box[2] <= canvas[0] and box[3] <= canvas[1], (
                box, canvas)
            b.shot("guided_9_after_reload.png")
            b.page.get_by_text("Lesion end (mm)").scroll_into_view_if_needed()
            b.shot("guided_10_results_panel.png")
            # The sliders' end labels as the page prints them (the lesion sliders' read
            # "91.722401", the window width's "32.99").
            ends = b.page.locator(".mantine-Slider-markLabel").all_inner_texts()
            assert ends and all(re.fullmatch(r"\d+(\.\d)?", e.strip()) for e in ends), ends

            # The proximal reference site, dragged with the mouse: the measurements and
            # the chart follow.
            m = rec.measurements
            thumb = b.slider_thumb("Proximal reference (mm)")
            thumb.scroll_into_view_if_needed()
            box = thumb.bounding_box()
            b.page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
            b.page.mouse.down()
            b.page.mouse.move(box["x"] - 40, box["y"] + box["height"] / 2, steps=8)
            b.page.mouse.up()
            wait_for(lambda: app.lesion is not None, 10, "the lesion to follow the slider")
            site = app.lesion["proximal_reference_s_mm"]
            assert site < m.lesion_start_s_mm - 2.0, (site, m.lesion_start_s_mm)
            assert app.lesion["lesion_start_s_mm"] == pytest.approx(m.lesion_start_s_mm, abs=0.1)
            assert f"(at {site:.1f} / " in app.panels.results.clinical.content
            b.page.wait_for_timeout(800)
            b.page.get_by_text("Distal reference (mm)").scroll_into_view_if_needed()
            b.shot("guided_11_reference_moved.png")

            with b.page.expect_download(timeout=30_000) as info:
                b.page.get_by_role("button", name="Download report.json").click()
            saved = tmp_path / "report.json"
            info.value.save_as(saved)
            assert json.loads(saved.read_text())["centerline"]["length_mm"] > 0
        finally:
            b.close()
            app.stop()


def _catheter_file(demo_a: Path, out: Path, row: float, cols: tuple[int, int],
                   french: float) -> float:
    """Demo view A with a straight contrast-filled catheter of ``french`` F along image
    row ``row`` between columns ``cols`` (Beer-Lambert, blurred as the detector), written
    as XA DICOM with the demo's header; returns its width in px (at the isocentre)."""
    from scipy import ndimage as ndi

    from recon.io import load_angiogram
    from recon.io.dicom_write import write_xa_dicom

    angio = load_angiogram(str(demo_a))
    g = angio.geometry
    width_px = french / 3.0 * g.sid_mm / g.sod_mm / g.pixel_spacing_mm[0]
    rows, colgrid = np.mgrid[0:g.rows, 0:g.cols].astype(float)
    chord = 2.0 * np.sqrt(np.clip((width_px / 2) ** 2 - (rows - row) ** 2, 0.0, None))
    chord[(colgrid < cols[0]) | (colgrid > cols[1])] = 0.0
    transmitted = ndi.gaussian_filter(np.exp(-0.09 * chord), 0.8)
    image = np.clip(np.round(angio.image * transmitted), 0, 4095).astype(np.uint16)
    write_xa_dicom(out, image, g, bits_stored=12)
    return width_px


@pytest.mark.skipif(not Path(CHROMIUM).is_file(), reason=f"no browser at {CHROMIUM}")
def test_catheter_calibration_sets_the_pixel_spacing_from_two_clicks(
    demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    """Issue 16: two clicks across the guiding catheter and its French size set the pixel
    spacing, in the Geometry folder, with real mouse events; the clicks are no marks."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    path_a = tmp_path / "catheter_a.dcm"
    row, french = 150.0, 6.0  # top right of A, clear of the notifications
    width_px = _catheter_file(demo_case["a"], path_a, row, (330, 500), french)
    app = ViewerApp(str(path_a), str(demo_case["b"]), None, port=0,
                    autosave_path=tmp_path / "autosave.json")
    app.wait_ready()
    true_spacing = app.views["a"].angio.geometry.pixel_spacing_mm[0]
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            b.open(app)
            b.page.get_by_text("Geometry", exact=True).click()  # unfold the folder
            field = b.text_field("Catheter size (F)")
            field.fill(f"{french:g}")
            field.press("Enter")
            b.page.get_by_role("button", name="Measure catheter (click its 2 edges)").click()
            wait_for(lambda: app.catheter.active, 10, "the catheter measurement to start")
            # One click near each edge, a pixel or so off, as a hand places them.
            _, notes = b.click("a", 420.0, row - width_px / 2 - 1.0)
            assert notes == []  # the panel's note answers, no toast over view A's title
            assert "First edge placed in **A**" in app.panels.geometry.catheter_note.content
            b.shot("catheter_0_first_edge.png")
            _, notes = b.click("a", 421.0, row + width_px / 2 + 0.7)
            assert app.state.marks == []  # catheter clicks are not marks
            cal = app.catheter.result
            assert cal is not None, notes
            assert cal.width_px == pytest.approx(width_px, rel=0.05)
            assert cal.pixel_spacing_mm == pytest.approx(true_spacing, rel=0.05)
            typed = app.panels.geometry.fields["a"]["pixel_spacing_mm"].value
            assert float(typed) == pytest.approx(cal.pixel_spacing_mm, abs=1e-4)
            b.page.wait_for_timeout(600)
            b.page.get_by_text("Catheter calibration").scroll_into_view_if_needed()
            b.shot("catheter_1_measured.png")
            # Opening with this geometry uses it; clicks are marks again.
            b.page.get_by_role("button", name="Open with this geometry").click()
            wait_for(lambda: abs(app.views["a"].angio.geometry.pixel_spacing_mm[0]
                              - float(typed)) < 1e-6, 30, "the pair to reopen")
            b.settle()
            mark, _ = b.click("a", 300.0, 300.0)
            assert mark is not None and mark.view == "a"
            assert app.panels.geometry.catheter_note.content == ""  # no stale figures
            b.shot("catheter_2_reopened.png")
        finally:
            b.close()
            app.stop()


@pytest.mark.skipif(not Path(CHROMIUM).is_file(), reason=f"no browser at {CHROMIUM}")
def test_a_branch_added_from_a_landmark_and_the_tree_shown_branch_by_branch(
    tmp_path: Path, artifacts_dir: Path
) -> None:
    """Issue 15's viewer item with the mouse: on IM7 / IM8 with the long arc and its
    diagonal branch marked, the clinician selects the upper bifurcation landmark, presses
    "New branch from landmark", clicks the new branch's waypoint and distal end in both
    views and reconstructs the three-branch tree; choosing a branch shows its numbers."""
    from recon.seeds import Seeds

    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    data = Path(__file__).resolve().parents[1] / "data"
    full = load_seeds(data / "im7_im8_tree_seeds.json")
    two = tmp_path / "two_branches.json"
    two.write_text(json.dumps(Seeds(segments=full.segments[:2], features=full.features)
                              .to_dict()))
    app = ViewerApp(str(data / "IM7.dcm"), str(data / "IM8.dcm"), str(two), port=0,
                    autosave_path=tmp_path / "autosave.json")
    app.wait_ready()
    upper = full.segments[2]
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            b.open(app)
            new_branch = b.page.get_by_role("button", name="New branch from landmark")
            new_branch.click()  # nothing selected: the page says what to click first
            b.page.get_by_text("New branch failed").first.wait_for(state="visible",
                                                                  timeout=10_000)
            b.shot("tree_0_no_landmark_selected.png")
            mark = next(m for m in app.state.marks if m.kind == "feature" and m.view == "b"
                        and app.state.feature_name(m.group) == "arc/upper")
            b.choose("Selected mark", f"B {app.state.label(mark)} #{mark.id}")
            wait_for(lambda: app.state.selected_id == mark.id, 10, "the landmark to be selected")
            new_branch.click()
            wait_for(lambda: len(app.state.segment_names) == 3, 10, "the new branch")
            assert app.state.segment_links["Segment 3"] == ("long arc", "arc/upper")
            wait_for(lambda: b.dropdown_value("Segment") == "Segment 3", 10,
                  "the page's Segment dropdown to show the branch")
            field = b.text_field("Segment name")  # the clinician names the branch
            field.fill("upper branch")
            b.page.get_by_role("button", name="Rename segment").click()
            wait_for(lambda: app.state.segment_names[2] == "upper branch", 10, "the rename")
            assert app.state.segment_links["upper branch"] == ("long arc", "arc/upper")
            assert "Segment 3" not in app.state.segment_links
            wait_for(lambda: b.dropdown_value("Segment") == "upper branch", 10,
                  "the page's Segment dropdown to show the new name")
            for view, pts in (("a", upper.a_px), ("b", upper.b_px)):
                new, notes = b.click(view, *pts[-1])  # guided: the distal end
                assert new is not None and new.kind == "distal", notes
            b.choose("Mode", MODE_LABELS["waypoint"])
            wait_for(lambda: app.state.mode == "waypoint", 10, "the mode")
            for view, pts in (("a", upper.a_px), ("b", upper.b_px)):
                new, notes = b.click(view, *pts[1])
                assert new is not None and new.kind == "waypoint", notes
            b.shot("tree_1_branch_marked.png")
            n_notes = len(app.notifications)  # the refusal above was an error already
            b.page.get_by_role("button", name="Reconstruct", exact=True).click()
            wait_for(lambda: any(n[0] == "error" or n[1] == "Reconstructed"  # drawn by then
                              for n in app.notifications[n_notes:]), 180, "the tree")
            rec = app.reconstruction
            assert rec is not None and len(getattr(rec, "branches", ())) == 3, \
                app.notifications[-3:]
            assert rec.seeds.segments[2].parent == "long arc"
            assert app.shown_branch == 2  # the current segment's branch
            b.page.wait_for_timeout(1500)
            b.shot("tree_2_reconstructed.png")
            branch = b.page.get_by_label("Branch", exact=True)
            branch.scroll_into_view_if_needed()
            b.choose("Branch", "diagonal branch")
            m = rec.branches[1].measurements
            wait_for(lambda: f"**{m.mld_mm:.2f} mm**" in app.panels.results.clinical.content, 10,
                  "the diagonal branch's table")
            assert app.shown_branch == 1
            assert app.state.segment_names[app.state.current_segment] == "diagonal branch"
            b.page.get_by_text(f"{m.mld_mm:.2f} mm").first.wait_for(state="visible",
                                                                   timeout=10_000)
            b.page.wait_for_timeout(800)
            b.shot("tree_3_diagonal_shown.png")
            b.page.get_by_text("Bifurcations").first.scroll_into_view_if_needed()
            b.shot("tree_4_bifurcations.png")
            b.choose("Show", "3D model")
            wait_for(lambda: app.layout == "3D model", 10, "the 3D model")
            b.page.wait_for_timeout(1000)
            b.shot("tree_5_model.png")
            ffr_box = b.page.get_by_text("Colour the model by FFR").first  # issue 47
            ffr_box.click()
            wait_for(lambda: app.ffr_colouring and app.panels.results.ffr_key.visible, 10,
                     "the tree coloured by FFR")
            b.page.wait_for_timeout(1000)
            b.shot("tree_5b_model_by_ffr.png")
            ffr_box.click()
            wait_for(lambda: not app.ffr_colouring, 10, "the tree coloured by branch")
            # Renamed after Reconstruct: the results shown take the name, no new run.
            b.choose("Show", "Angiograms + 3D")
            field = b.text_field("Segment name")
            field.fill("D1")
            b.page.get_by_role("button", name="Rename segment").click()
            wait_for(lambda: b.dropdown_value("Branch") == "D1", 10,
                  "the page's Branch dropdown to show the new name")
            assert "long arc › D1" in app.panels.results.bifurcations.content
            b.page.get_by_text("Branch shown: D1").first.wait_for(state="visible",
                                                                  timeout=10_000)
            b.page.wait_for_timeout(800)
            b.shot("tree_6_renamed.png")
        finally:
            b.close()
            app.stop()
