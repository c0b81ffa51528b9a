"""The page's zoom in headless Chromium with real mouse events (issue 46: the guiding
catheter was about 6 screen px wide, too small to click its edges): x4 and a click on a
place of one image show that place four times larger, clicks then place marks where they
land, and Fit shows both images whole again. Screenshots go to test-artifacts/viewer/."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from browser_page import CHROMIUM, Browser, demo_page, wait_for  # tests/viewer_app/browser_page.py

pytestmark = pytest.mark.browser


def _px_per_image_px(b: Browser, view: str, col: float, row: float) -> float:
    """Screen px per image px at (col, row) of ``view`` (from the page's own camera)."""
    x0, y0 = b.screen_xy(view, col, row)
    x1, y1 = b.screen_xy(view, col + 20.0, row)
    return float(np.hypot(x1 - x0, y1 - y0)) / 20.0


@pytest.mark.skipif(not Path(CHROMIUM).is_file(), reason=f"no browser at {CHROMIUM}")
def test_zoom_shows_one_place_larger_and_fit_shows_both_images(
    demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    place = (170.0, 440.0)  # the hairpin bend near the demo vessel's distal end in A
    with demo_page(demo_case, tmp_path, artifacts_dir, seeds=False) as (app, b):
        n_marks = len(app.state.marks)
        scale_fit = _px_per_image_px(b, "a", *place)
        b.page.get_by_role("button", name="x4", exact=True).click()
        wait_for(lambda: app.zoom_pending == 4, 10, "the zoom to wait for its place")
        assert "Click the place to look at" in app.panels.results.zoom_note.content
        mark, notes = b.click("a", *place)
        assert mark is None and len(app.state.marks) == n_marks, notes  # no mark
        assert app.zoom is not None and app.zoom[0] == "a" and app.zoom[2] == 4
        assert np.allclose(app.zoom[1], place, atol=1.5)
        b.page.wait_for_timeout(2000)  # the camera moves
        wait_for(lambda: _px_per_image_px(b, "a", *place) > 3.5 * scale_fit, 10,
                 "the image to be shown four times larger")
        # the place is in the middle of the canvas, and a click there places a mark
        x, y = b.screen_xy("a", *place)
        box = b.page.locator("canvas").first.bounding_box()
        assert abs(x - (box["x"] + box["width"] / 2)) < 0.1 * box["width"]
        assert abs(y - (box["y"] + box["height"] / 2)) < 0.1 * box["height"]
        b.shot("zoom_1_x4_on_a.png")
        mark, notes = b.click("a", place[0] + 3.0, place[1] - 2.0)
        assert mark is not None and mark.view == "a", notes
        assert np.hypot(mark.raw_px[0] - place[0] - 3.0, mark.raw_px[1] - place[1] + 2.0) < 1.0
        b.page.get_by_role("button", name="Fit", exact=True).click()
        wait_for(lambda: app.zoom is None, 10, "Fit")
        b.page.wait_for_timeout(2000)
        wait_for(lambda: abs(_px_per_image_px(b, "a", *place) / scale_fit - 1.0) < 0.05, 10,
                 "both images whole again")
        assert not app.panels.results.zoom_note.visible
        b.shot("zoom_2_fit.png")
