"""Issue 47 on the page, in headless Chromium with real mouse events: the demo
reconstructed from the page shows the FFR (a model estimate for research) in the results
table, its pullback chart with the research-use lines under it, and the model can be
coloured by FFR with a colour key and back. Screenshots go to
test-artifacts/viewer/ffr_*.png.
"""

from __future__ import annotations

import io
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh
from browser_page import (
    CANVAS_JS,
    CHROMIUM,
    PROJECT_JS,
    Browser,
    demo_page,
    failed,
    screen_box,
    wait_for,
)

from recon.lumen.ffr import RESEARCH_NOTE
from viewer_app import ViewerApp
from viewer_app.model_colours import ffr_colors, vertex_ffr
from viewer_app.plot import ffr_plot

pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(not Path(CHROMIUM).is_file(), reason=f"no browser at {CHROMIUM}")]

CHECKBOX = "Colour the model by FFR"
SHOWN_IMAGES_JS = """
([w, h]) => [...document.images].filter((i) => i.naturalWidth === w
  && i.naturalHeight === h && i.offsetParent !== null && i.complete).length
"""


def _mesh_rgb(app: ViewerApp) -> np.ndarray:
    """The vertex colours (V, 3) of the model's mesh as the server sent it."""
    glb = app.server.scene.get_handle_by_name("/model/mesh").glb_data
    (mesh,) = trimesh.load(io.BytesIO(glb), file_type="glb").geometry.values()
    return np.asarray(mesh.visual.vertex_colors)[:, :3]


def _visible_text(b: Browser, text: str) -> None:
    found = b.page.get_by_text(text).first
    found.scroll_into_view_if_needed()
    found.wait_for(state="visible", timeout=10_000)


#: A label's size on the screen at viser's default font (CSS px), measured on the
#: screenshots: about 5.6 px per character, 12 px high.
LABEL_CHAR_PX, LABEL_HEIGHT_PX = 5.6, 12.0


def _label_box(b: Browser, app: ViewerApp, name: str) -> tuple[float, ...]:
    """The screen box (x0, x1, y0, y1) of the model's label ``name``: its position through
    the page's own camera, its size from its text and anchor."""
    handle = app.server.scene.get_handle_by_name(name)
    x, y = b.page.evaluate(PROJECT_JS, ["/model", *map(float, handle.position)])
    w = LABEL_CHAR_PX * len(handle.text.splitlines()[0])
    vertical, horizontal = handle.anchor.split("-")
    x0 = x - {"left": 0.0, "center": w / 2, "right": w}[horizontal]
    y0 = y - {"top": 0.0, "center": LABEL_HEIGHT_PX / 2, "bottom": LABEL_HEIGHT_PX}[vertical]
    return x0, x0 + w, y0, y0 + LABEL_HEIGHT_PX


def _apart(b: Browser, app: ViewerApp, *names: str) -> None:
    """The model's labels ``names`` do not print over each other on the screen."""
    boxes = [_label_box(b, app, n) for n in names]
    for i, p in enumerate(boxes):
        for q in boxes[i + 1:]:
            assert p[1] <= q[0] or q[1] <= p[0] or p[3] <= q[2] or q[3] <= p[2], (names, boxes)


def test_the_ffr_on_the_page_chart_table_and_the_model_coloured(
    demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    with demo_page(demo_case, tmp_path, artifacts_dir) as (app, b):
        assert not b.page.get_by_text(CHECKBOX).first.is_visible()  # nothing to colour
        b.page.get_by_role("button", name="Reconstruct", exact=True).click()
        wait_for(lambda: app.reconstruction is not None or failed(app), 180,
                 "the reconstruction")
        rec = app.reconstruction
        assert rec is not None and rec.ffr is not None, app.notifications[-3:]
        ffr = rec.ffr
        r = app.panels.results
        b.page.wait_for_timeout(1500)

        # The table: the distal FFR with its 95 % interval, said to be a model
        # estimate for research; the flow assumption's band apart from it.
        lo, hi = ffr.ci95
        value = f"{ffr.distal:.2f} (95 % {lo:.2f}–{hi:.2f})"
        assert value.split(" (")[0] in r.clinical.content
        _visible_text(b, "FFR, distal (model estimate for research")
        _visible_text(b, f"(95 % {lo:.2f}–{hi:.2f})")
        _visible_text(b, "not a confidence interval")
        b.shot("ffr_0_table.png")

        # The chart and, under it, the research-use sentence, both on the screen.
        assert r.ffr_plot.visible and np.array_equal(r.ffr_plot.image,
                                                    ffr_plot(rec, width=440, height=346))
        chart = b.page.get_by_text("FFR along the vessel", exact=True).first
        chart.scroll_into_view_if_needed()
        chart.wait_for(state="visible", timeout=10_000)
        assert b.page.evaluate(SHOWN_IMAGES_JS, [440, 346]) == 1  # the chart, drawn
        note = b.page.get_by_text("Research use only.").first
        note.scroll_into_view_if_needed()
        note.wait_for(state="visible", timeout=10_000)
        assert RESEARCH_NOTE in r.ffr_note.content
        _visible_text(b, "not validated against a pressure wire here")
        b.shot("ffr_1_chart.png")

        # The model coloured by FFR with the mouse: every vertex the FFR of its
        # nearest centerline point, the key and the distal value shown; and back.
        before = _mesh_rgb(app)
        box = b.page.get_by_text(CHECKBOX).first
        box.scroll_into_view_if_needed()
        box.click()
        wait_for(lambda: app.ffr_colouring and r.ffr_key.visible, 10,
                 "the model to be coloured by FFR")
        mesh = rec.surface.mesh
        expected = ffr_colors(vertex_ffr([rec], np.asarray(mesh.vertices)))
        wait_for(lambda: np.array_equal(_mesh_rgb(app), expected), 10, "the FFR colours")
        distal = app.server.scene.get_handle_by_name("/model/ffr_values/b0")
        assert distal is not None and distal.text.startswith(f"distal FFR {ffr.distal:.2f}")
        title = app.server.scene.get_handle_by_name("/model/title").text
        assert "coloured by FFR" in title and "research use" in title
        b.page.wait_for_timeout(1500)
        _apart(b, app, "/model/ffr_values/b0", "/model/mld_label")
        b.shot("ffr_2_model_coloured.png")
        b.page.get_by_text(CHECKBOX).first.scroll_into_view_if_needed()
        assert b.page.evaluate(SHOWN_IMAGES_JS, [360, 112]) == 1  # the colour key
        b.shot("ffr_3_key.png")
        b.choose("Show", "3D model")
        wait_for(lambda: app.layout == "3D model", 10, "the 3D model")
        b.page.wait_for_timeout(1200)
        model = screen_box(b, "/model/mesh")  # whole: its near end was cut off
        canvas = b.page.evaluate(CANVAS_JS)
        assert model[0] >= 0 and model[1] >= 0 and model[2] <= canvas[0] \
            and model[3] <= canvas[1], (model, canvas)
        _apart(b, app, "/model/ffr_values/b0", "/model/mld_label")
        b.shot("ffr_4_model_alone.png")
        b.choose("Show", "Angiograms + 3D")
        wait_for(lambda: app.layout == "Angiograms + 3D", 10, "the layout")
        b.page.get_by_text(CHECKBOX).first.click()
        wait_for(lambda: not app.ffr_colouring and not r.ffr_key.visible, 10,
                 "the colours by diameter")
        wait_for(lambda: np.array_equal(_mesh_rgb(app), before), 10, "the diameter colours")
        assert app.server.scene.get_handle_by_name("/model/ffr_values/b0") is None

        # An FFR that could not be computed: said, with its reason; no chart, nothing
        # to colour by.
        reason = "FFR not computed: FFR: segment 'Segment 1': the lumen closes at 20.0 mm"
        with app._lock:
            app.reconstruction = replace(rec, ffr=None, warnings=(*rec.warnings, reason))
            app._show_reconstruction(app.reconstruction)
        assert not r.ffr_plot.visible and r.ffr_colour.disabled
        _visible_text(b, "FFR not computed: segment 'Segment 1': the lumen closes")
        b.page.wait_for_timeout(600)
        b.shot("ffr_5_not_computed.png")
