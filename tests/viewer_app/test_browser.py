"""The viewer in headless Chromium: page ready, click on image A, reconstruct, download.

One fat test (the first WebGL render costs seconds on a small machine).
Screenshots go to test-artifacts/viewer/. Needs /usr/bin/chromium and the
``playwright`` package (no ``playwright install``: the system Chromium is used).
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from recon.io import load_seeds
from viewer_app import ViewerApp

CHROMIUM = "/usr/bin/chromium"
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-unsafe-swiftshader",
]

pytestmark = pytest.mark.browser

# node-local point -> CSS pixel of the page, through the node's world matrix
# (the root of viser's scene is rotated) and the three.js camera.
PROJECT_JS = """
([name, x, y, z]) => {
  const m = window.__viserMutable;
  const ref = m.nodeRefFromName[name];
  const node = ref && ref.current !== undefined ? ref.current : ref;
  const cam = m.camera && m.camera.current !== undefined ? m.camera.current : m.camera;
  const canvas = m.canvas && m.canvas.current !== undefined ? m.canvas.current : m.canvas;
  node.updateWorldMatrix(true, false);
  const p = new node.position.constructor(x, y, z).applyMatrix4(node.matrixWorld).project(cam);
  const r = canvas.getBoundingClientRect();
  return [r.left + (p.x + 1) / 2 * r.width, r.top + (1 - p.y) / 2 * r.height];
}
"""

READY_JS = """
() => {
  const m = window.__viserMutable;
  if (!m || !m.nodeRefFromName) return false;
  if (document.body.innerText.includes("Connecting")) return false;
  return ["/view_a", "/view_b", "/over_a/marks"].every((n) => {
    const r = m.nodeRefFromName[n];
    return r && (r.current !== undefined ? r.current : r);
  });
}
"""


def _wait(predicate, timeout_s: float, what: str) -> None:
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        if predicate():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}")


@pytest.mark.skipif(not Path(CHROMIUM).is_file(), reason=f"no browser at {CHROMIUM}")
def test_clinician_session_in_chromium(
    app: ViewerApp, demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path
) -> None:
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    out = artifacts_dir
    app.clear()
    with sync_api.sync_playwright() as pw:
        ctx = pw.chromium.launch_persistent_context(
            str(tmp_path / "chromium-profile"),
            executable_path=CHROMIUM,
            args=FLAGS,
            headless=True,
            viewport={"width": 1400, "height": 900},
            accept_downloads=True,
        )
        try:
            page = ctx.new_page()
            t0 = time.perf_counter()
            page.goto(app.url)
            page.wait_for_function(READY_JS, timeout=30_000)
            ready_s = time.perf_counter() - t0
            page.wait_for_timeout(1500)  # let the nodes fade in before the screenshot
            (out / "page_ready_s.txt").write_text(f"{ready_s:.2f}\n")
            page.screenshot(path=str(out / "1_ready.png"))
            assert ready_s < 30.0

            # Click on image A at a known pixel: a mark appears, snapped or raw,
            # with the epipolar line in B.
            va = app.views["a"]
            col, row = load_seeds(demo_case["seeds"]).segments[0].a_px[0]
            local = va.local_from_px(np.array([[col, row]]), z=0.0)[0]
            app.set_mode("proximal")
            n_before = len(app.state.marks)
            x, y = page.evaluate(PROJECT_JS, ["/view_a", *map(float, local)])
            page.mouse.click(x, y)
            _wait(lambda: len(app.state.marks) > n_before, 10, "the click to reach the server")
            mark = app.state.marks[-1]
            assert mark.view == "a" and mark.kind == "proximal"
            assert np.hypot(mark.raw_px[0] - col, mark.raw_px[1] - row) < 2.0
            assert app.epipolar_segments["b"] is not None
            page.wait_for_timeout(500)
            page.screenshot(path=str(out / "2_click.png"))

            # Reconstruct from the GUI button on the demo seeds.
            app.load_seeds(demo_case["seeds"])
            page.get_by_role("button", name="Reconstruct").click()
            _wait(lambda: app.reconstruction is not None or _failed(app), 180, "reconstruction")
            assert app.reconstruction is not None, app.notifications[-3:]
            page.wait_for_timeout(1500)
            page.screenshot(path=str(out / "3_reconstructed.png"))
            page.get_by_role("button", name="Camera: images + model").click()
            page.wait_for_timeout(1500)
            page.screenshot(path=str(out / "4_all.png"))
            page.get_by_text("Diameter along the vessel").scroll_into_view_if_needed()
            page.wait_for_timeout(500)
            page.screenshot(path=str(out / "5_results_panel.png"))

            # A download reaches the browser.
            with page.expect_download(timeout=30_000) as info:
                page.get_by_role("button", name="Download report.json").click()
            dl = info.value
            assert dl.suggested_filename == "report.json"
            saved = tmp_path / "report.json"
            dl.save_as(saved)
            report = json.loads(saved.read_text())
            assert report["centerline"]["length_mm"] > 0
        finally:
            ctx.close()
    shutil.rmtree(tmp_path / "chromium-profile", ignore_errors=True)


def _failed(app: ViewerApp) -> bool:
    return any(level == "error" for level, _, _ in app.notifications)
