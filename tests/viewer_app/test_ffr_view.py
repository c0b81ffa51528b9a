"""Issue 47 on the page, without a browser: the FFR's colours on the model, its pullback
chart, its rows in the results table and the research-use lines, and the app's
"Colour the model by FFR" on the demo."""

from __future__ import annotations

import io
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from recon.lumen.ffr import RESEARCH_NOTE, FFRModel
from viewer_app import ViewerApp
from viewer_app.model_colours import (
    FFR_CUTOFF,
    FFR_GREY,
    centerline_ffr,
    ffr_colors,
    ffr_key_image,
    segment_diameter_colors,
    vertex_ffr,
)
from viewer_app.plot import FFR_BAND, FFR_CURVE, FFR_CUT, FFR_INTERVAL, ffr_plot
from viewer_app.results import clinical_markdown, ffr_note, ffr_rows


def test_the_colours_change_at_the_cut_off() -> None:
    rgb = ffr_colors(np.array([0.5, 0.7, 0.79, FFR_CUTOFF, 0.801, 0.9, 1.0, np.nan])).astype(int)
    low, high = rgb[:4], rgb[4:7]
    assert np.all(low[:, 0] > low[:, 2] + 80)  # red / orange at or below 0.80
    assert np.all(high[:, 2] > high[:, 0] + 50)  # blue above
    assert np.abs(rgb[3] - rgb[4]).sum() > 200  # a step at the cut-off, not a blend
    assert np.abs(rgb[2] - rgb[3]).sum() < 40  # ... and none just below it
    assert np.all(rgb[0] < rgb[1]) and np.all(high[2] <= high[0])  # darker further out
    assert tuple(rgb[-1]) == FFR_GREY
    key = ffr_key_image()
    assert key.shape == (112, 360, 3) and not key.flags.writeable
    bar = key[36, 24:336].astype(int)  # the scale, 0.50 to 1.00 left to right
    assert bar[0, 0] > bar[0, 2] and bar[-1, 2] > bar[-1, 0]


def _rec(with_ci: bool = True, ffr_start_mm: float = 0.0) -> SimpleNamespace:
    """A stand-in: a straight 50 mm segment along x, its FFR falling from 1.0 to 0.7 at
    25 mm (from ``ffr_start_mm``, a branch's carina), the flow band +- 0.05 around it."""
    s = np.linspace(0.0, 50.0, 201)
    ffr_s = s[s >= ffr_start_mm]
    values = 1.0 - 0.3 / (1.0 + np.exp(-(ffr_s - 25.0)))
    ffr = SimpleNamespace(
        s_mm=ffr_s, ffr=values, model=FFRModel(), flow_ml_s=2.0, n_draws=32 if with_ci else 0,
        ffr_lo=values - 0.04 if with_ci else None, ffr_hi=values + 0.04 if with_ci else None,
        band=np.stack([values + 0.05, values - 0.05]),
        distal=float(values[-1]), ci95=(float(values[-1] - 0.04), float(values[-1] + 0.04))
        if with_ci else None, flow_band=(float(values[-1] - 0.05), float(values[-1] + 0.05)))
    profile = SimpleNamespace(s_mm=s, diameter_smooth_mm=np.full_like(s, 3.0),
                              reference_diameter_mm=np.full_like(s, 3.0))
    cl = SimpleNamespace(s_mm=s, X_world=np.column_stack([s, np.zeros_like(s),
                                                          np.zeros_like(s)]))
    return SimpleNamespace(ffr=ffr, profile=profile, centerline_3d=cl, warnings=(),
                           lesions=None)


def test_each_vertex_takes_the_ffr_of_its_nearest_centerline_point() -> None:
    rec = _rec(ffr_start_mm=5.0)  # a branch: its pullback starts at its carina
    values = centerline_ffr(rec)
    s = rec.centerline_3d.s_mm
    assert np.allclose(values[s <= 5.0], rec.ffr.ffr[0])  # before the carina: the first
    np.testing.assert_allclose(values[s >= 5.0], rec.ffr.ffr)
    vertices = np.array([[10.0, 1.5, 0.0], [40.0, 0.0, -1.5], [2.0, 1.5, 0.0]])
    expected = np.interp([10.0, 40.0, 2.0], rec.ffr.s_mm, rec.ffr.ffr)
    np.testing.assert_allclose(vertex_ffr([rec], vertices), expected)
    # Two parts: a vertex takes its nearest part's own FFR, NaN for a part without one.
    other = _rec()
    other.centerline_3d = SimpleNamespace(s_mm=s, X_world=rec.centerline_3d.X_world + [0, 20, 0])
    other.ffr = None
    v = vertex_ffr([rec, other], np.array([[40.0, 1.0, 0.0], [40.0, 19.0, 0.0]]))
    assert v[0] == pytest.approx(np.interp(40.0, rec.ffr.s_mm, rec.ffr.ffr)) and np.isnan(v[1])
    assert centerline_ffr(other) is None
    assert np.array_equal(segment_diameter_colors(rec, vertices)[0], [40, 180, 70])  # green


def _rows_of(img: np.ndarray, colour: tuple[int, int, int], col: int) -> np.ndarray:
    return np.flatnonzero(np.all(img[:, col] == colour, axis=-1))


def test_the_chart_draws_the_pullback_its_interval_the_flow_band_and_the_cut_off() -> None:
    rec = _rec()
    img = ffr_plot(rec)
    assert img.shape == (346, 440, 3) and img.dtype == np.uint8
    # The mapping: left 56, right 14, top 34, bottom 114 px; FFR from 0.60 (the lowest
    # shown, 0.66, less 0.03, down to 0.05) to 1.02.
    left, right, top, bottom, y0, y1 = 56, 14, 34, 114, 0.60, 1.02

    def row_of(f: float) -> float:
        return 346 - bottom - (f - y0) / (y1 - y0) * (346 - top - bottom)

    for s_mm in (10.0, 40.0):
        col = round(left + s_mm / 50.0 * (440 - left - right))
        f = float(np.interp(s_mm, rec.ffr.s_mm, rec.ffr.ffr))
        curve = _rows_of(img, FFR_CURVE, col)
        assert curve.size and abs(np.median(curve) - row_of(f)) <= 2.0, (s_mm, curve)
        if s_mm == 40.0:  # the interval shaded between f - 0.04 and f + 0.04
            shaded = _rows_of(img, FFR_INTERVAL, col)
            assert shaded.min() <= row_of(f + 0.035) and shaded.max() >= row_of(f - 0.035)
    cut = _rows_of(img, FFR_CUT, 200)  # the 0.80 line across the chart
    assert cut.size and abs(np.median(cut) - row_of(FFR_CUTOFF)) <= 1.0
    chart = img[top:346 - bottom, left:440 - right]
    assert np.count_nonzero(np.all(chart == FFR_BAND, axis=-1)) > 100  # the dashes
    no_ci = ffr_plot(_rec(with_ci=False))[top:346 - bottom, left:440 - right]
    assert not np.any(np.all(no_ci == FFR_INTERVAL, axis=-1))


def test_the_table_rows_and_the_lines_under_the_chart() -> None:
    rec = _rec()
    rows = ffr_rows(rec)
    lo, hi = rec.ffr.ci95
    assert rows[0] == (f"| FFR, distal (model estimate for research) | "
                       f"**{rec.ffr.distal:.2f}** (95 % {lo:.2f}–{hi:.2f}) |")
    blo, bhi = rec.ffr.flow_band
    assert rows[1] == (f"| FFR over the flow assumption (0.25–0.45 m/s) | {blo:.2f}–{bhi:.2f}, "
                       "not a confidence interval |")
    assert "(no 95 % interval)" in ffr_rows(_rec(with_ci=False))[0]
    note = ffr_note(rec)
    assert "Research use only" in note and RESEARCH_NOTE in note
    assert "not validated against a pressure wire" in note
    none = SimpleNamespace(ffr=None, warnings=(
        "view B overlapped", "FFR not computed: FFR: segment 'LAD' is 4.0 mm long; at least "
        "5 mm is needed"))
    assert ffr_rows(none) == ["| FFR (model estimate for research) | not computed: segment "
                              "'LAD' is 4.0 mm long; at least 5 mm is needed |"]
    assert ffr_note(none) == ("⚠ **FFR not computed: segment 'LAD' is 4.0 mm long; at least "
                              "5 mm is needed**")


def _mesh_rgb(app: ViewerApp) -> np.ndarray:
    glb = app.server.scene.get_handle_by_name("/model/mesh").glb_data
    (mesh,) = trimesh.load(io.BytesIO(glb), file_type="glb").geometry.values()
    return np.asarray(mesh.visual.vertex_colors)[:, :3]


def test_the_app_colours_the_model_by_ffr_and_back(app: ViewerApp) -> None:
    assert app.set_ffr_colouring(True) is False  # nothing to colour yet; the choice holds
    rec = app.reconstruct()
    assert rec is not None and rec.ffr is not None, app.notifications[-3:]
    r = app.panels.results
    vertices = np.asarray(rec.surface.mesh.vertices)
    by_ffr = ffr_colors(vertex_ffr([rec], vertices))
    assert np.array_equal(_mesh_rgb(app), by_ffr)  # coloured at once: the box was ticked
    assert r.ffr_colour.value and not r.ffr_colour.disabled and r.ffr_key.visible
    assert "coloured by FFR" in app.server.scene.get_handle_by_name("/model/title").text
    label = app.server.scene.get_handle_by_name("/model/ffr_values/b0").text
    lo, hi = rec.ffr.ci95
    assert label == f"distal FFR {rec.ffr.distal:.2f} (95 % {lo:.2f}-{hi:.2f})"
    # the lesion's stretch is coloured by the FFR there, not by its diameter
    assert len({tuple(c) for c in _mesh_rgb(app)}) > 5
    assert clinical_markdown(rec).count("FFR") >= 2 and ffr_rows(rec)[0] in r.clinical.content
    assert r.ffr_plot.visible and np.array_equal(r.ffr_plot.image, ffr_plot(rec))
    assert r.ffr_note.visible and RESEARCH_NOTE in r.ffr_note.content

    assert app.set_ffr_colouring(False) is False
    assert np.array_equal(_mesh_rgb(app), segment_diameter_colors(rec, vertices))
    assert not r.ffr_key.visible and not r.ffr_colour.value
    assert app.server.scene.get_handle_by_name("/model/ffr_values/b0") is None
    assert "green = reference diameter" in app.server.scene.get_handle_by_name(
        "/model/title").text

    # No FFR (the model refused the lumen): said with its reason, no chart, the box off.
    note = "FFR not computed: FFR: segment 'Segment 1': the lumen closes at 20.0 mm"
    with app._lock:
        app.reconstruction = replace(rec, ffr=None, warnings=(*rec.warnings, note))
        app._show_reconstruction(app.reconstruction)
    assert app.set_ffr_colouring(True) is False
    assert np.array_equal(_mesh_rgb(app), segment_diameter_colors(rec, vertices))
    assert not r.ffr_plot.visible and r.ffr_colour.disabled and not r.ffr_key.visible
    assert "FFR not computed: segment 'Segment 1': the lumen closes" in r.ffr_note.content
    assert "not computed: segment 'Segment 1'" in r.clinical.content
    app.clear()  # Clear marks: no FFR left on the page
    assert not (r.ffr_plot.visible or r.ffr_note.visible or r.ffr_colour.visible)
