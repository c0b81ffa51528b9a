"""ViewerApp on the demo case, served by a real in-process viser server, without a browser."""

from __future__ import annotations

import io
import json
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
import trimesh

from recon.io import load_seeds
from recon.seeds import seeds_from_dict
from viewer_app import ViewerApp, run_viewer
from viewer_app.plot import BRANCH_BAND
from viewer_app.results import branch_stretches


def _line_distance_px(seg: np.ndarray, point_px: np.ndarray) -> float:
    """Distance of a point (2,) to the infinite line through a segment (2, 2)."""
    d = seg[1] - seg[0]
    w = np.asarray(point_px, dtype=float) - seg[0]
    return float(abs(d[0] * w[1] - d[1] * w[0]) / np.linalg.norm(d))


def test_server_binds_localhost_on_a_free_port(app: ViewerApp) -> None:
    assert app.url == f"http://127.0.0.1:{app.port}/?token={app.server_guard.token}"
    assert len(app.server_guard.token) >= 32
    assert app.port > 0
    with urllib.request.urlopen(app.url, timeout=10) as resp:
        assert resp.status == 200
    assert set(app.views) == {"a", "b"}
    assert app.seeds().segments, "the demo seeds are loaded on start"


def test_clicks_snap_to_the_vessel_and_draw_the_epipolar_line(
    app: ViewerApp, demo_case: dict[str, Path], artifacts_dir: Path
) -> None:
    seeds = load_seeds(demo_case["seeds"])
    col, row = seeds.segments[0].a_px[0]
    app.wait_ready()  # vesselness maps computed (in the background since start)
    app.clear()
    app.set_mode("proximal")
    mark = app.click("a", col + 1.5, row - 1.0)  # a clinician's click, a bit off
    assert mark is not None and mark.kind == "proximal" and mark.view == "a"
    assert mark.snap_distance_px is not None, app.notifications[-1:]
    assert mark.point_px != mark.raw_px
    epi = app.epipolar_segments
    assert epi["a"] is None and epi["b"] is not None
    assert app.views["a"].nodes.marks.points.shape == (1, 3)
    assert app.views["b"].nodes.epipolar.points.shape == (1, 2, 3)
    timings_ms = [app.last_click_ms]
    for dx in (-1.0, 0.5, 1.0, -0.5):  # more clicks for the figure in the report
        app.click("a", col + dx, row + dx)
        timings_ms.append(app.last_click_ms)
    (artifacts_dir / "click_to_epipolar_ms.txt").write_text(
        f"median {np.median(timings_ms):.2f} ms, max {np.max(timings_ms):.2f} ms "
        f"over {len(timings_ms)} clicks (server side)\n"
    )

    # Far from any vessel: kept raw, and the user is told in the marks panel (a toast
    # would cover the left of image A, where the next click goes).
    n_notes = len(app.notifications)
    corner = app.click("a", 2.0, 2.0)
    assert corner is not None and corner.snap_distance_px is None
    assert corner.point_px == corner.raw_px == (2.0, 2.0)
    assert len(app.notifications) == n_notes
    assert "not snapped" in app.panels.marks.summary.content

    # Feature pair: A then B; undo removes the last click.
    app.set_mode("feature")
    app.click("a", *seeds.segments[0].a_px[-1])
    app.click("b", *seeds.segments[0].b_px[-1])
    assert len(app.seeds().features) == 1
    assert app.undo()
    assert len(app.seeds().features) == 0
    app.clear()
    assert app.state.marks == []
    assert app.views["a"].nodes.marks.points.shape == (0, 3)


def test_calibration_moves_epipolar_lines_onto_the_partner_points(app: ViewerApp) -> None:
    st = app.state
    pairs = [(m, st.partner(m)) for m in st.marks if m.view == "a" and st.partner(m) is not None]
    assert len(pairs) >= 2

    def worst_distance() -> float:
        dists = []
        for mark, partner in pairs:
            app.select(mark.id)
            view, seg = "b", app.epipolar_segments["b"]
            assert seg is not None, view
            dists.append(_line_distance_px(seg, np.asarray(partner.point_px)))
        return max(dists)

    before = worst_distance()
    res = app.calibrate()
    assert res is not None, app.notifications[-1:]
    after = worst_distance()
    assert after < 2.0 < before
    assert "error (px)" in app.panels.calibrate.markdown.content


def test_reconstruct_then_export(app: ViewerApp) -> None:
    rec = app.reconstruct()
    assert rec is not None, app.notifications[-3:]
    stages = [s for s, _ in app.progress_log]
    assert stages[0] != stages[-1] and app.progress_log[-1][1] == 1.0
    assert len(rec.surface.mesh.faces) > 100
    for key in ("a", "b"):  # traced and back-projected centerlines on both images
        assert len(app.views[key].nodes.trace.points) > 10
        assert len(app.views[key].nodes.backproj.points) > 10
    table = app.panels.results.markdown.content
    assert table.startswith("| measurement | value |") and "| Table 3 |" in table
    assert app.panels.results.plot.visible
    m = rec.measurements
    clinical = app.panels.results.clinical.content
    ci = rec.intervals.ci95  # report.json measurements_ci95, beside each figure (issue 14)
    assert (f"| Minimal lumen diameter | **{m.mld_mm:.2f} mm** ({ci['mld_mm'][0]:.2f}–"
            f"{ci['mld_mm'][1]:.2f}) |") in clinical
    lo, hi = ci["diameter_stenosis_pct"]
    assert (f"| % diameter stenosis | **{m.diameter_stenosis_pct:.0f} %** ({lo:.0f}–{hi:.0f})"
            " |") in clinical
    lo, hi = ci["lesion_length_mm"]
    assert f"| Lesion length | {m.lesion_length_mm:.1f} mm ({lo:.1f}–{hi:.1f}), from " in clinical
    # The lesion sliders' ends are on their 0.1 mm grid (the page printed "91.722401").
    s = rec.profile.s_mm
    for h in (app.panels.results.lesion_start, app.panels.results.lesion_end):
        assert f"{h.max:g}" == f"{h.max:.1f}".rstrip("0").rstrip(".")
        assert f"{h.min:g}" == f"{h.min:.1f}".rstrip("0").rstrip(".")
        assert s[0] <= h.min < s[0] + 0.1 and s[-1] - 0.1 < h.max <= s[-1]
    # The demo's side branch (feature "bifurcation 1", at 21.5 mm in truth.json) widens
    # the measured diameter by ~0.5 mm: the spike is in the profile, not the chart, and
    # the page says where it is rather than hiding it.
    excess = rec.profile.diameter_mm - rec.profile.reference_diameter_mm
    near = (s > 10.0) & (s < 40.0)
    s_spike = float(s[near][np.argmax(excess[near])])
    assert float(np.max(excess[near])) > 0.3
    (branch,) = branch_stretches(rec)
    assert abs(branch["s_mm"] - 21.5) < 1.0 and branch["start_mm"] < s_spike < branch["end_mm"]
    assert f"Side branch at {branch['s_mm']:.1f} mm (bifurcation 1)" in clinical
    chart = app.panels.results.plot.image
    assert np.count_nonzero(np.all(chart == BRANCH_BAND, axis=-1)) > 500
    assert "Table 3" not in clinical and "ms" not in clinical  # engineering folded away
    # Moving the lesion ends: the measurements, chart and marks follow.
    start, end = m.lesion_start_s_mm - 3.0, m.lesion_end_s_mm + 3.0
    lesion = app.set_lesion(start, end)
    assert lesion["lesion_length_mm"] == pytest.approx(end - start)
    assert lesion["mld_mm"] == pytest.approx(
        float(np.min(rec.profile.diameter_smooth_mm[(rec.profile.s_mm >= start)
                                                    & (rec.profile.s_mm <= end)])))
    assert "set by hand" in app.panels.results.clinical.content
    # ... and the reference sites (default: the lesion ends), each with its slider.
    assert app.panels.results.reference_proximal.visible
    assert lesion["proximal_reference_s_mm"] == pytest.approx(start)
    moved = app.set_lesion(start, end, (start - 5.0, end + 5.0))
    assert moved["mld_mm"] == lesion["mld_mm"]
    assert moved["proximal_reference_mm"] == pytest.approx(float(np.interp(
        start - 5.0, rec.profile.s_mm, rec.profile.diameter_smooth_mm)))
    assert f"(at {start - 5.0:.1f} / {end + 5.0:.1f} mm)" in app.panels.results.clinical.content
    assert "reference site is in it" not in app.panels.results.clinical.content
    # A reference site in the side branch's stretch is named (its diameter is not the
    # lumen's alone); the screenshot of a dragged slider showed one there.
    app.set_lesion(start, end, (branch["s_mm"] + 1.0, end + 5.0))
    assert "the proximal reference site is in it" in app.panels.results.clinical.content
    assert f"{end - start:.1f} mm" in app.panels.results.clinical.content

    stl = app.export("stl")
    mesh = trimesh.load(io.BytesIO(stl), file_type="stl")
    assert len(mesh.faces) == len(rec.surface.mesh.faces)
    for fmt in ("obj", "ply", "glb"):
        assert len(app.export(fmt)) > 1000
    csv = app.export("centerline.csv").decode()
    assert csv.splitlines()[0].startswith("s_mm,x_mm,y_mm,z_mm")
    assert len(csv.splitlines()) > 10
    report = json.loads(app.export("report.json"))
    assert report["centerline"]["length_mm"] > 0
    seeds = seeds_from_dict(json.loads(app.export("seeds.json")))
    assert seeds == app.seeds()


def test_export_before_reconstruct_is_a_user_error(app: ViewerApp) -> None:
    try:
        app.export("stl")
    except ValueError as exc:
        assert "reconstruct first" in str(exc)
    else:
        raise AssertionError("export without a reconstruction must raise ValueError")
    app.download("stl")  # through the GUI path: a notification, not an exception
    assert app.notifications[-1][0] == "error"


def test_bad_files_become_notifications(app: ViewerApp, tmp_path: Path) -> None:
    bad = tmp_path / "not_a_dicom.dcm"
    bad.write_bytes(b"this is not DICOM")
    good_b = app.views["b"].angio.path
    assert app.open_pair(str(bad), good_b) is False
    level, title, body = app.notifications[-1]
    assert level == "error" and "not_a_dicom.dcm" in body and "\n" not in body
    assert app.open_upload("a", "upload.dcm", b"garbage") is False
    assert app.notifications[-1][0] == "error"
    broken_seeds = tmp_path / "seeds.json"
    broken_seeds.write_text("{not json")
    assert app.load_seeds(broken_seeds) is False
    assert app.notifications[-1][0] == "error"
    assert app.calibrate is not None and app.click("a", 100.0, 100.0) is not None  # still alive


def test_views_too_similar_are_named_as_soon_as_the_pair_is_open(app: ViewerApp) -> None:
    """Issue 16: a pair less than 25 degrees apart is named in the page when it opens,
    before any Calibrate or Reconstruct (the pipeline would refuse it)."""
    from recon.geometry import view_separation_deg
    from recon.io.overrides import GeometryOverrides

    assert not app.panels.marks.warning.visible  # the demo's views are 60 degrees apart
    ga = app.views["a"].angio.geometry
    near = GeometryOverrides(alpha_deg=ga.alpha_deg + 10.0, beta_deg=ga.beta_deg)
    path_a, path_b = app.views["a"].angio.path, app.views["b"].angio.path
    n = len(app.notifications)
    assert app.open_pair(path_a, path_b, overrides_b=near)
    separation = view_separation_deg(ga, app.views["b"].angio.geometry)
    assert 5.0 < separation < 25.0
    warned = [(level, body) for level, title, body in app.notifications[n:]
              if title == "Views too similar"]
    assert warned and warned[0][0] == "warning" and f"{separation:.0f}°" in warned[0][1]
    assert app.panels.marks.warning.visible
    assert "Views too similar" in app.panels.marks.warning.content
    assert "Views too similar" in app.panels.case.info.content
    assert app.reconstruction is None and app.calibration is None
    assert app.open_pair(path_a, path_b)  # a pair far enough apart: the warning goes
    assert not app.panels.marks.warning.visible


def test_marks_are_autosaved_and_restored(demo_case: dict[str, Path], tmp_path: Path) -> None:
    autosave = tmp_path / "out" / "seeds.autosave.json"
    kwargs = dict(host="127.0.0.1", port=0, autosave_path=autosave, out_dir=tmp_path)
    first = ViewerApp(str(demo_case["a"]), str(demo_case["b"]), None, **kwargs)
    try:
        first.set_mode("waypoint")
        first.click("a", 150.0, 160.0)
        first.set_mode("feature")
        first.click("a", 200.0, 210.0)
        marks = [(m.kind, m.view, m.point_px) for m in first.state.marks]
    finally:
        first.stop()
    assert autosave.is_file()
    second = ViewerApp(str(demo_case["a"]), str(demo_case["b"]), None, **kwargs)
    try:
        assert second.restored_autosave
        assert [(m.kind, m.view, m.point_px) for m in second.state.marks] == marks
        path = tmp_path / "saved_seeds.json"
        second.save_seeds(path)
        assert load_seeds(path) == second.seeds()
    finally:
        second.stop()


def test_run_viewer_reports_its_url_and_stops(demo_case: dict[str, Path], tmp_path: Path) -> None:
    urls: list[str] = []
    ready = threading.Event()
    stop = threading.Event()

    def on_ready(url: str) -> None:
        urls.append(url)
        ready.set()

    thread = threading.Thread(
        target=run_viewer,
        args=(str(demo_case["a"]), str(demo_case["b"]), str(demo_case["seeds"])),
        kwargs=dict(port=0, on_ready=on_ready, autosave_path=tmp_path / "a.json",
                    stop_event=stop),
        daemon=True,
    )
    thread.start()
    assert ready.wait(30)
    assert urls[0].startswith("http://127.0.0.1:")
    with urllib.request.urlopen(urls[0], timeout=10) as resp:
        assert resp.status == 200
    stop.set()
    thread.join(10)
    assert not thread.is_alive()


def test_cine_frame_slider_and_missing_geometry(tmp_path: Path) -> None:
    data = Path(__file__).resolve().parents[1] / "data"
    app = ViewerApp(str(data / "IM7.dcm"), str(data / "IM8.dcm"), None, host="127.0.0.1",
                    port=0, autosave_path=tmp_path / "auto.json")
    try:
        slider = app.panels.case.views["a"].frame
        # frame numbers from 1, as the case table says them (issue 46: it was 0-based)
        assert slider.visible and (slider.min, slider.max) == (1, 9)
        assert slider.value == app.views["a"].angio.frame_index + 1  # the loader's choice
        assert f"| frame | {int(slider.value)}/9 |" in app.panels.case.info.content
        before = app.views["a"].nodes.image.image.copy()
        slider.value = 2  # as if the user dragged it to frame 2
        assert app.views["a"].angio.frame_index == 1
        assert not np.array_equal(app.views["a"].nodes.image.image, before)
        # A real clinical cine without SID/SOD/spacing: an error notification, the app lives on,
        # and the Geometry folder asks for the three values (IM8's prefilled from its header).
        assert app.open_pair(str(data / "rca-cine-ecg.dcm"), str(data / "IM8.dcm")) is False
        level, _, body = app.notifications[-1]
        assert level == "error" and "DistanceSourceToDetector" in body
        assert "enter it under Geometry" in body and "--sid-mm" not in body
        assert app.views["a"].angio.path.endswith("IM7.dcm")
        entries = app.panels.geometry.entries()
        assert entries["a"] == {"sid_mm": "", "sod_mm": "", "pixel_spacing_mm": ""}
        im8 = app.views["b"].angio.geometry
        assert float(entries["b"]["sid_mm"]) == pytest.approx(im8.sid_mm)
        entries["a"] = {"sid_mm": "1000", "sod_mm": "750", "pixel_spacing_mm": "0.3"}
        n_notes = len(app.notifications)
        assert app.apply_geometry(entries)
        a, b = app.views["a"].angio, app.views["b"].angio
        assert a.path.endswith("rca-cine-ecg.dcm") and a.geometry.sid_mm == 1000.0
        assert a.geometry.sod_mm == 750.0 and a.geometry.pixel_spacing_mm == (0.3, 0.3)
        assert b.geometry.sid_mm == pytest.approx(im8.sid_mm)  # IM8's own header, untouched
        # no header value was replaced (the autosave of the earlier pair is kept aside:
        # that notice is the autosave's, tested in test_autosave)
        assert not [n for n in app.notifications[n_notes:]
                    if n[0] == "warning" and n[1] != "Autosave kept aside"]
        # A typed value that differs from a header's replaces it, and says so.
        entries = app.panels.geometry.entries()
        entries["b"]["sid_mm"] = f"{im8.sid_mm + 100:g}"
        assert app.apply_geometry(entries)
        assert app.views["b"].angio.geometry.sid_mm == pytest.approx(im8.sid_mm + 100)
        level, title, body = app.notifications[-1]
        assert level == "warning" and "replaces the header's" in body and "IM8" in body
    finally:
        app.stop()


def test_the_intensity_choice_of_each_view_reaches_the_reconstruction(app: ViewerApp) -> None:
    app.panels.case.views["b"].intensity.value = "log"  # the panel's dropdown
    deadline = time.monotonic() + 5.0
    while app.intensity["b"] != "log" and time.monotonic() < deadline:
        time.sleep(0.05)
    assert app.intensity == {"a": "auto", "b": "log"}
    with pytest.raises(ValueError):
        app.set_intensity("a", "gamma")
    rec = app.reconstruct()
    assert rec.options.intensity_a == "auto" and rec.options.intensity_b == "log"
    report = rec.report()["intensity"]
    assert report["b"]["mapping"] == "log" and "set by the user" in report["b"]["reason"]


def test_reconstruct_past_its_memory_limit_says_which_and_the_viewer_goes_on(
        app: ViewerApp) -> None:
    app.limits = (0.02, None)  # as --max-memory-gb 0.02
    assert app.reconstruct() is None
    level, title, body = app.notifications[-1]
    assert (level, title) == ("error", "Reconstruct failed")
    assert body.startswith("the reconstruction needed more memory than its limit of 0.02 GB "
                           "(--max-memory-gb")
    app.limits = (None, None)
    assert app.reconstruct() is not None  # the server was not touched by the limit


def test_a_refused_trace_is_ringed_where_it_asks_for_a_waypoint(app: ViewerApp) -> None:
    """Issue 13: a trace the tool refuses is named in one line and its place is ringed on
    its view (through the reconstruction's child process); a reconstruction that runs
    removes the ring."""
    from dataclasses import replace

    from recon.seeds import Seeds

    seeds = app.seeds()
    seg = seeds.segments[0]
    a = seg.a_px  # proximal, two waypoints, distal: the distal end clicked second
    out_of_order = (a[0], a[-1], a[1], a[2])
    app.state.load_seeds(Seeds(segments=(replace(seg, a_px=out_of_order),),
                               features=seeds.features))
    assert app.reconstruct() is None
    level, title, body = app.notifications[-1]
    assert (level, title) == ("error", "Reconstruct failed")
    assert body.startswith("view A: the trace doubles back at click 2 ") and "\n" not in body
    ring = app.server.scene.get_handle_by_name("/over_a/refusal")
    assert ring is not None and app.server.scene.get_handle_by_name("/over_b/refusal") is None
    centre_local = ring.points.reshape(-1, 3)[:, :2].mean(axis=0)
    centre_px = app.views["a"].px_from_local(centre_local)
    assert np.hypot(*(centre_px - np.asarray(a[-1]))) < 3.0  # round the second click
    assert app.server.scene.get_handle_by_name("/over_a/refusal_label") is not None

    app.state.load_seeds(seeds)
    assert app.reconstruct() is not None
    assert app.server.scene.get_handle_by_name("/over_a/refusal") is None
    # Clearing the marks (or loading others) removes a ring the old marks caused.
    app.state.load_seeds(Seeds(segments=(replace(seg, a_px=out_of_order),),
                               features=seeds.features))
    assert app.reconstruct() is None
    assert app.server.scene.get_handle_by_name("/over_a/refusal") is not None
    app.clear()
    assert app.server.scene.get_handle_by_name("/over_a/refusal") is None


def test_results_of_earlier_marks_are_marked_and_a_failed_run_removes_them(
        app: ViewerApp) -> None:
    """Issue 46 item 2: a mark added after Reconstruct marks the results and the
    calibration out of date (panels, over both images, beside the model) and its Undo
    unmarks them; a failed Reconstruct removes every result of before (model, traces,
    MLD, off-vessel tags, tables, chart, calibration), its refusal ring staying."""
    from dataclasses import replace

    from recon.seeds import Seeds
    from viewer_app.results import NO_RECONSTRUCTION_TEXT, NOT_CALIBRATED_TEXT

    scene_ = app.server.scene
    seeds = app.seeds()
    assert app.reconstruct() is not None
    results, calibrate = app.panels.results, app.panels.calibrate
    assert not results.stale.visible and not calibrate.stale.visible
    assert scene_.get_handle_by_name("/over_a/out_of_date") is None
    app.set_mode("waypoint")
    assert app.click("a", 250.0, 250.0) is not None
    assert results.stale.visible and "Out of date" in results.stale.content
    assert calibrate.stale.visible
    for name in ("/over_a/out_of_date", "/over_b/out_of_date", "/model/out_of_date"):
        assert scene_.get_handle_by_name(name) is not None, name
    assert app.undo()
    assert not results.stale.visible and not calibrate.stale.visible
    assert scene_.get_handle_by_name("/over_a/out_of_date") is None
    assert scene_.get_handle_by_name("/model/out_of_date") is None

    seg = seeds.segments[0]
    a = seg.a_px  # the distal end clicked second: the trace is refused
    app.load_seeds_upload(json.dumps(Seeds(segments=(replace(seg, a_px=(a[0], a[-1], a[1],
                                                                       a[2])),),
                                           features=seeds.features).to_dict()).encode())
    assert app.reconstruct() is None
    assert app.reconstruction is None and app.model is None and app.calibration is None
    assert scene_.get_handle_by_name("/model") is None
    for key in ("a", "b"):
        assert len(app.views[key].nodes.trace.points) == 0
        for name in ("lesion", "lesion_labels", "flagged", "flag_labels", "out_of_date"):
            assert scene_.get_handle_by_name(f"/over_{key}/{name}") is None, name
    assert results.clinical.content == NO_RECONSTRUCTION_TEXT and not results.plot.visible
    assert calibrate.markdown.content == NOT_CALIBRATED_TEXT
    assert not results.stale.visible and app.layout == "Angiograms"
    assert scene_.get_handle_by_name("/over_a/refusal") is not None


def test_the_current_segment_is_renamed_from_the_name_field(app: ViewerApp) -> None:
    """The Name field shows the current segment's name; Rename segment renames it (a taken
    name is a notification, the field keeping what was typed), and a name being typed stays
    in the field while marks are placed."""
    app.load_seeds_upload(json.dumps(app.seeds().to_dict()).encode())
    marks = app.panels.marks
    assert marks.name.value == app.state.segment_names[0]
    assert app.rename_segment("LAD") == "LAD"
    assert marks.name.value == "LAD" and tuple(marks.segment.options) == ("LAD",)
    assert app.seeds().segments[0].name == "LAD"
    index = app.new_segment()
    assert marks.name.value == app.state.segment_names[index] != "LAD"
    marks.name.value = "LAD"
    assert app.rename_segment(marks.name.value) is None
    assert app.notifications[-1][:2] == ("error", "Rename failed")
    assert "already called 'LAD'" in app.notifications[-1][2]
    app.set_mode("feature")
    app.click("a", 100.0, 100.0)  # a mark placed while a name is being typed
    assert marks.name.value == "LAD"
    assert app.undo() and app.undo() and app.undo()
    assert app.state.segment_names == [app.seeds().segments[0].name] != ["LAD"]


def test_a_rename_after_reconstruct_reaches_the_results_and_clearing_the_marks_removes_them(
        app: ViewerApp) -> None:
    """One segment reconstructed, then renamed: report.json names it as renamed (the
    results stay current: a name changes no figure). Clear marks removes the results and
    the calibration (issue 46 item 2); Undo brings the marks and their name back, not the
    results of before."""
    rec = app.reconstruct()
    assert rec is not None, app.notifications[-3:]
    assert app.rename_segment("LAD") == "LAD"
    assert json.loads(app.export("report.json"))["inputs"]["segment"] == "LAD"
    assert app.reconstruction.seeds.segments[0].name == "LAD"
    assert not app.panels.results.stale.visible
    app.clear()
    assert app.state.segment_names == ["Segment 1"]
    assert app.reconstruction is None and app.calibration is None and app.model is None
    assert app.state.view_b_calibrated is None  # epipolar lines of the header again
    with pytest.raises(ValueError, match="reconstruct first"):
        app.export("report.json")
    assert app.undo()  # the marks back, and the name their undo restores: LAD
    assert app.state.segment_names == ["LAD"]
    assert app.reconstruction is None


def test_a_catheter_found_is_drawn_dashed_and_reported(app: ViewerApp) -> None:
    """Issue 13: the guiding catheter a view's trace was kept off is drawn on that view
    (dashed, labelled at its tip) and listed in report.json; the demo shows none."""
    from dataclasses import replace

    from viewer_app.scene import CATHETER_DASH_PX, clear_results, draw_catheters

    rec = app.reconstruct()
    assert rec is not None, app.notifications[-3:]
    assert rec.report()["guiding_catheter"] == {"a": [], "b": []}
    dashes = app.server.scene.get_handle_by_name("/over_b/catheter")
    assert dashes is not None and len(dashes.points) == 0
    rows = app.views["b"].rows
    tube = np.column_stack([np.full(61, 100.0), np.linspace(0.0, rows / 2, 61)])
    rec2 = replace(rec, centerline_b=replace(rec.centerline_b, catheters_px=(tube,)))
    assert draw_catheters(app.server.scene, app.views, rec2) == 1
    dashes = app.server.scene.get_handle_by_name("/over_b/catheter")
    n_dashes = len(dashes.points)
    assert n_dashes == pytest.approx(rows / 2 / CATHETER_DASH_PX / 2, abs=1)
    ends_px = app.views["b"].px_from_local(dashes.points.reshape(-1, 3)[:, :2])
    assert np.abs(ends_px[:, 0] - 100.0).max() < 0.5  # on the tube's centre line
    label = app.server.scene.get_handle_by_name("/over_b/catheter_label")
    assert label is not None
    report = rec2.report()["guiding_catheter"]
    assert report["a"] == [] and report["b"][0]["tip_px"] == [100.0, round(rows / 2, 1)]
    clear_results(app.server.scene, app.views)
    assert app.server.scene.get_handle_by_name("/over_b/catheter") is None


def _other_patient_copy(src: Path, out: Path, patient_id: str = "OTHER-PATIENT-4711") -> Path:
    """A copy of ``src`` whose PatientID is another patient's (changed with pydicom)."""
    import pydicom

    ds = pydicom.dcmread(src)
    ds.PatientID = patient_id
    ds.save_as(out)
    return out


def test_two_patients_are_refused_until_the_page_confirms_them(
        app: ViewerApp, demo_case: dict[str, Path], tmp_path: Path,
        caplog: pytest.LogCaptureFixture) -> None:
    """Issue 46 item 3: a pair whose files name different patients opens with the warning
    and its button shown, Calibrate and Reconstruct refuse, and the confirmation lets them
    run; the patient ID itself is nowhere on the page nor in the log."""
    other = _other_patient_copy(demo_case["b"], tmp_path / "b_other.dcm")
    app.access.add_read_root(tmp_path)
    assert not app.patients_differ and not app.panels.marks.patients.visible
    with caplog.at_level("DEBUG"):
        assert app.open_pair(str(demo_case["a"]), str(other))
        assert app.patients_differ and not app.patients_confirmed
        marks = app.panels.marks
        assert marks.patients.visible and marks.confirm_patients.visible
        assert "different patients" in marks.patients.content
        app.load_seeds(str(demo_case["seeds"]))
        assert app.calibrate() is None and app.reconstruct() is None
        assert app.notifications[-1][2].startswith("files A and B name different patients")
        assert app.reconstruction is None
        app.confirm_one_patient()
        assert not marks.patients.visible and not marks.confirm_patients.visible
        assert app.reconstruct() is not None, app.notifications[-3:]
    shown = " ".join(str(x) for n in app.notifications for x in n) + marks.patients.content \
        + app.panels.case.info.content
    assert "OTHER-PATIENT-4711" not in shown and "OTHER-PATIENT-4711" not in caplog.text
    # One patient's files again: no warning, nothing to confirm.
    assert app.open_pair(str(demo_case["a"]), str(demo_case["b"]))
    assert not app.patients_differ and not app.panels.marks.patients.visible


def test_a_mark_is_moved_by_a_drag_in_one_undo_step_and_the_selected_one_deleted(
        app: ViewerApp, tmp_path: Path) -> None:
    """Issue 46 item 8 without the browser: a drag that starts on a mark's dot grabs it,
    moves it raw, snaps it where it ends, autosaves it, and one Undo undoes it; a drag
    that starts away from every mark grabs none; Delete removes the selected mark."""
    app.wait_ready()
    mark = next(m for m in app.state.marks if m.view == "a" and m.kind == "distal")
    assert app.grab_mark("a", 5.0, 5.0) is None  # no mark there
    assert app.drag_mark_to(100.0, 100.0, final=True) is None
    grabbed = app.grab_mark("a", mark.point_px[0] + 3.0, mark.point_px[1] - 2.0)
    assert grabbed == mark and app.state.selected_id == mark.id
    waypoint = [m for m in app.state.marks if m.view == "a" and m.kind == "waypoint"][-1]
    goal = (np.asarray(mark.point_px) + waypoint.point_px) / 2  # along the vessel
    raw = app.drag_mark_to(*(goal + [3.0, 3.0]))
    assert raw.snap_distance_px is None and raw.point_px == tuple(goal + [3.0, 3.0])
    moved = app.drag_mark_to(*goal, final=True)
    assert moved.id == mark.id and moved.snap_distance_px is not None
    assert np.hypot(*(np.asarray(moved.point_px) - goal)) < 8.0
    saved = json.loads(app.autosave.path.read_text())
    assert moved.point_px in [tuple(p) for s in saved["segments"] for p in s["a"]]
    assert app.undo() and app.state.mark_by_id(mark.id) == mark  # one step for the drag
    assert app.move_mark(mark.id, *goal) is not None
    assert app.undo() and app.state.mark_by_id(mark.id) == mark
    app.select(mark.id)
    assert app.delete_selected() == mark and app.state.mark_by_id(mark.id) is None
    assert app.delete_selected() is None
    assert app.notifications[-1][:2] == ("error", "Delete mark failed")
    assert app.undo() and app.state.mark_by_id(mark.id) == mark
    app.catheter.pending = ("a", 6.0)  # a catheter measurement waits: drags move no mark
    assert app.grab_mark("a", *mark.point_px) is None


def test_the_mld_s_name_on_an_image_clears_the_marks_labels(
        app: ViewerApp, demo_case: dict[str, Path]) -> None:
    """Issue 46: "MLD" printed over a landmark's "F2" next to it; its name now goes where
    it clears every mark's dot and label on both images."""
    from recon.geometry import ViewGeometry
    from viewer_app.placing import (
        DOT_RADIUS,
        MARK_LABEL_WIDTH,
        NAME_CHAR,
        label_box,
        label_places,
    )

    truth = json.loads(Path(demo_case["a"]).with_name("truth.json").read_text())

    # a landmark on the MLD itself in both views: the place the issue saw
    X = np.asarray(truth["segment"]["X_world"], dtype=float)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(X, axis=0), axis=1))])
    at = X[int(np.argmin(np.abs(s - truth["stenosis"]["s_mm"])))][None]
    app.set_mode("feature")
    app.click("a", *ViewGeometry.from_dict(truth["view_a"]).project(at)[0])
    app.click("b", *ViewGeometry.from_dict(truth["view_b_true"]).project(at)[0])
    assert app.reconstruct() is not None, app.notifications[-3:]
    for key in ("a", "b"):
        label = app.server.scene.get_handle_by_name(f"/over_{key}/lesion_labels/mld")
        pts = np.asarray(app.views[key].nodes.marks.points, dtype=float)
        boxes = [np.array([x - DOT_RADIUS, x + DOT_RADIUS, y - DOT_RADIUS, y + DOT_RADIUS])
                 for x, y in pts[:, :2]]
        boxes += [label_box(p[:2] + off[:2], anchor, MARK_LABEL_WIDTH)
                  for p, (off, anchor) in zip(pts, label_places(pts), strict=True)]
        mld = label_box(np.asarray(label.position)[:2], label.anchor, NAME_CHAR * 3)
        hits = [b for b in boxes
                if b[1] > mld[0] and b[0] < mld[1] and b[3] > mld[2] and b[2] < mld[3]]
        assert not hits, (key, mld, hits)


def test_an_upload_is_named_by_its_own_name_not_the_private_folder(app: ViewerApp) -> None:
    """Issue 46: a toast showed the viewer's internal temporary path of an upload."""
    from viewer_app.app import public_paths

    assert not app.open_upload("b", "scan.dcm", b"not a DICOM file")
    level, _, body = app.notifications[-1]
    assert level == "error" and "scan.dcm" in body
    assert app._tmpdir.name not in body and "coronary3d-viewer-" not in body
    private = "/tmp/coronary3d-viewer-x1"
    assert public_paths(f"{private}/a-17/IM1.dcm: bad", private) == "IM1.dcm: bad"
    assert public_paths(f"{private}/seeds-99.json: bad", private) == \
        "the uploaded seeds file: bad"
