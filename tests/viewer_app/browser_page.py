"""The browser side of the viewer tests: one headless Chromium (Playwright, the system
/usr/bin/chromium) on a ViewerApp's page, clicks as real mouse events on image pixels,
screenshots into test-artifacts/viewer/, and the page's scene read through viser's
``window.__viserMutable``."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

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


DISMISS_JS = """
() => {  // close the 'Software WebGL rendering' toast (a GPU-less machine only)
  for (const n of document.querySelectorAll('.mantine-Notification-root')) {
    if (n.innerText.includes('Software WebGL')) {
      const b = n.querySelector('button'); if (b) b.click();
    }
  }
}
"""

MARK_LABELS_JS = """
() => Object.keys(window.__viserMutable.nodeRefFromName)  // scene nodes of the mark labels
  .filter((n) => /[/]labels[/]m[0-9]+$/.test(n))
"""


def wait_for(predicate, timeout_s: float, what: str) -> None:
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        if predicate():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}")


class Browser:
    """One Chromium (Playwright) with a page on a viewer; clicks are real mouse events."""

    def __init__(self, pw: object, profile: Path, out: Path) -> None:
        self.ctx = pw.chromium.launch_persistent_context(
            str(profile), executable_path=CHROMIUM, args=FLAGS, headless=True,
            viewport={"width": 1400, "height": 900}, accept_downloads=True)
        self.page = self.ctx.new_page()
        self.out = out
        self.shots: list[str] = []

    def open(self, app: ViewerApp) -> None:
        self.app = app
        self.page.goto(app.url)
        self.settle()

    def reload(self) -> None:
        self.page.reload()
        self.settle()

    def settle(self) -> None:
        self.page.wait_for_function(READY_JS, timeout=30_000)
        self.page.wait_for_timeout(1500)  # nodes fade in, the canvas takes its size
        self.page.evaluate(DISMISS_JS)
        self.page.wait_for_timeout(300)

    def shot(self, name: str) -> None:
        self.page.wait_for_timeout(400)
        # a loaded machine renders WebGL slowly (30 s was once not enough for the fonts)
        self.page.screenshot(path=str(self.out / name), timeout=120_000)
        self.shots.append(name)

    def screen_xy(self, view: str, col: float, row: float) -> tuple[float, float]:
        local = self.app.views[view].local_from_px(np.array([[col, row]]), z=0.0)[0]
        x, y = self.page.evaluate(PROJECT_JS, [f"/view_{view}", *map(float, local)])
        return float(x), float(y)

    def click(self, view: str, col: float, row: float) -> tuple[object, list]:
        """Click pixel (col, row) of image ``view``; returns (the new mark or None, the
        notifications it raised)."""
        app = self.app
        x, y = self.screen_xy(view, col, row)
        n_clicks, n_marks, n_notes = app.clicks_handled, app.state._next_id, len(app.notifications)
        self.page.mouse.click(x, y)
        try:
            wait_for(lambda: app.clicks_handled > n_clicks, 15,
                  f"the click on {view.upper()} ({col:.0f}, {row:.0f}) at screen "
                  f"({x:.0f}, {y:.0f}) to reach the server")
        except AssertionError:
            self.page.screenshot(path=str(self.out / "click_not_received.png"))
            raise
        new = [m for m in app.state.marks if m.id >= n_marks]
        return (new[-1] if new else None), app.notifications[n_notes:]

    def choose(self, label: str, option: str) -> None:
        """Pick ``option`` in the dropdown labelled ``label`` (mouse clicks)."""
        self.page.get_by_label(label, exact=True).click()
        self.page.get_by_role("option", name=option, exact=True).click()

    def text_field(self, label: str) -> object:
        """The text input labelled ``label`` (viser's label is not linked to its input)."""
        page = self.page
        row = page.locator("div").filter(has=page.get_by_text(label, exact=True))
        return row.filter(has=page.locator("input")).last.locator("input").first

    def slider_thumb(self, label: str) -> object:
        """The thumb of the slider labelled ``label``."""
        page = self.page
        row = page.locator("div").filter(has=page.get_by_text(label, exact=True))
        return row.filter(has=page.locator(".mantine-Slider-thumb")).last.locator(
            ".mantine-Slider-thumb").first

    def dropdown_value(self, label: str) -> str:
        return self.page.get_by_label(label, exact=True).input_value()

    def close(self) -> None:
        self.ctx.close()


CANVAS_JS = """
() => { const m = window.__viserMutable; const c = m.canvas.current ?? m.canvas;
        const r = c.getBoundingClientRect(); return [r.right, r.bottom]; }
"""

BOX_JS = """
(name) => {
  const m = window.__viserMutable;
  const ref = m.nodeRefFromName[name];
  const node = ref && ref.current !== undefined ? ref.current : ref;
  const cam = m.camera.current ?? m.camera;
  const canvas = m.canvas.current ?? m.canvas;
  node.updateWorldMatrix(true, true);
  const r = canvas.getBoundingClientRect();
  const xs = [], ys = [];
  node.traverse((o) => {
    if (!o.geometry || !o.geometry.attributes.position) return;
    const p = o.geometry.attributes.position;
    for (let i = 0; i < p.count; i += 7) {
      const v = new node.position.constructor(p.getX(i), p.getY(i), p.getZ(i))
        .applyMatrix4(o.matrixWorld).project(cam);
      xs.push(r.left + (v.x + 1) / 2 * r.width); ys.push(r.top + (1 - v.y) / 2 * r.height);
    }
  });
  return [Math.min(...xs), Math.min(...ys), Math.max(...xs), Math.max(...ys)];
}
"""


def screen_box(b: Browser, name: str) -> list[float]:
    return b.page.evaluate(BOX_JS, name)


def failed(app: ViewerApp) -> bool:
    return any(level == "error" for level, _, _ in app.notifications)




@contextlib.contextmanager
def demo_page(demo_case: dict[str, Path], tmp_path: Path, artifacts_dir: Path,
              seeds: bool = True) -> Iterator[tuple[ViewerApp, Browser]]:
    """A viewer on the demo pair (with its seeds, or none), ready, and a Chromium page
    open on it; both closed afterwards."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    app = ViewerApp(str(demo_case["a"]), str(demo_case["b"]),
                    str(demo_case["seeds"]) if seeds else None, port=0,
                    autosave_path=tmp_path / "autosave.json")
    app.wait_ready()
    with sync_api.sync_playwright() as pw:
        b = Browser(pw, tmp_path / "profile", artifacts_dir)
        try:
            b.open(app)
            yield app, b
        finally:
            b.close()
            app.stop()
