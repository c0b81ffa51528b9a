"""The clinician's viewer: two angiograms, marks, calibration, reconstruction, export.

One browser page served by viser. The scene holds both angiograms side by
side as image planes (view A left, view B right) with their marks, epipolar
lines and traces drawn as children of the image nodes; the reconstructed
mesh and 3D centerline appear above them. Every numerical step goes through
``recon`` (the same code as ``coronary3d reconstruct``).

Scene layout (viser world units; the scene's up direction is -y so that the
image rows run downwards on screen and the camera looks along +z):

- ``/view_a``, ``/view_b``: image planes, longer side :data:`IMAGE_SIZE`
  units, node-local x along the columns and y down the rows;
- ``/model``: the reconstruction, rotated into view A's frame (so it first
  looks like view A) and scaled to :data:`MODEL_SIZE` units, above the images.
"""

from __future__ import annotations

import logging
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import viser
from numpy.typing import NDArray

from recon.dicom_io import Angiogram, load_angiogram
from recon.seeds import Seeds, load_seeds, save_seeds
from viewer_app.state import (
    MODE_LABELS,
    MODES,
    Autosave,
    Mark,
    MarkState,
    default_autosave_path,
)

__all__ = ["ViewerApp", "run_viewer", "DEMO_DIR", "EXPORT_KINDS"]

log = logging.getLogger(__name__)

DEMO_DIR = Path(__file__).resolve().parents[1] / "assets" / "demo"
IMAGE_SIZE = 1.0  # scene units of an image's longer side
IMAGE_GAP = 0.08  # between the two images
MODEL_SIZE = 1.0  # scene units of the model's longest extent
PANEL_SHIFT = 0.5  # camera x offset so the content sits left of the control panel
OVERLAY_Z = -0.002  # overlays a hair in front of the image plane (towards the camera)
SNAP_MAX_PX = 8.0
MESH_FORMATS = ("stl", "obj", "ply", "glb")
EXPORT_KINDS = (*MESH_FORMATS, "centerline.csv", "report.json", "seeds.json")

KIND_COLORS = {
    "proximal": (40, 220, 60),
    "waypoint": (255, 210, 0),
    "distal": (240, 50, 50),
    "feature": (0, 200, 255),
}
EPIPOLAR_COLOR = (255, 0, 255)
TRACE_COLOR = (255, 140, 0)
MESH_COLOR = (205, 70, 70, 255)
BACKPROJ_COLOR = (0, 255, 160)

FloatArray = NDArray[np.float64]


def _rgb_from_image(image: NDArray, level: float, width: float) -> NDArray[np.uint8]:
    """Window/level a raw (H, W) image to an RGB uint8 (H, W, 3) array."""
    lo = level - width / 2.0
    grey = np.clip((image.astype(np.float32) - lo) / max(width, 1e-6), 0.0, 1.0)
    g8 = (grey * 255.0 + 0.5).astype(np.uint8)
    return np.repeat(g8[:, :, None], 3, axis=2)


def _default_window(image: NDArray) -> tuple[float, float]:
    lo, hi = np.percentile(image, [0.5, 99.5])
    if hi <= lo:
        hi = lo + 1.0
    return float((lo + hi) / 2.0), float(hi - lo)


def _angle_text(alpha_deg: float, beta_deg: float) -> str:
    a = f"{'LAO' if alpha_deg >= 0 else 'RAO'} {abs(alpha_deg):.1f}°"
    b = f"{'CRA' if beta_deg >= 0 else 'CAU'} {abs(beta_deg):.1f}°"
    return f"{a} / {b}"


def _fmt(value: object) -> str:
    if isinstance(value, float | np.floating):
        return f"{float(value):.3g}" if abs(float(value)) < 1e4 else f"{float(value):.0f}"
    if isinstance(value, list | tuple):
        return ", ".join(_fmt(v) for v in value)
    return str(value)


def _polyline_segments(points: FloatArray) -> FloatArray:
    """(N, 3) polyline -> (N - 1, 2, 3) segments."""
    p = np.asarray(points, dtype=float)
    if len(p) < 2:
        return np.zeros((0, 2, 3))
    return np.stack([p[:-1], p[1:]], axis=1)


def _profile_plot(rec: object, width: int = 640, height: int = 360) -> NDArray[np.uint8]:
    """Diameter along the vessel as an RGB image (H, W, 3): measured, reference, MLD, lesion."""
    prof = rec.profile
    s = np.asarray(prof.s_mm, dtype=float)
    d = np.asarray(prof.diameter_mm, dtype=float)
    ref = np.asarray(prof.reference_diameter_mm, dtype=float)
    meas = rec.measurements.to_dict()
    img = np.full((height, width, 3), 255, np.uint8)
    left, right, top, bottom = 56, 14, 26, 40
    x0, x1 = float(s.min()), float(max(s.max(), s.min() + 1e-6))
    ymax = float(np.nanmax(np.concatenate([d, ref]))) * 1.15 or 1.0

    def px(sv: NDArray, dv: NDArray) -> NDArray[np.int32]:
        xs = left + (np.asarray(sv) - x0) / (x1 - x0) * (width - left - right)
        ys = height - bottom - np.asarray(dv) / ymax * (height - top - bottom)
        return np.stack([xs, ys], axis=-1).round().astype(np.int32)

    font = cv2.FONT_HERSHEY_SIMPLEX
    lesion = (meas.get("lesion_start_s_mm"), meas.get("lesion_end_s_mm"))
    if all(v is not None for v in lesion):
        a, b = px(np.array(lesion, float), np.zeros(2))
        cv2.rectangle(img, (int(a[0]), top), (int(b[0]), height - bottom), (255, 225, 225), -1)
        for p in (a, b):
            cv2.line(img, (int(p[0]), top), (int(p[0]), height - bottom), (220, 60, 60), 1)
    cv2.rectangle(img, (left, top), (width - right, height - bottom), (120, 120, 120), 1)
    for k in range(6):  # axis ticks
        yv = ymax * k / 5
        y = int(px(np.array([x0]), np.array([yv]))[0, 1])
        cv2.putText(img, f"{yv:.1f}", (4, y + 4), font, 0.4, (60, 60, 60), 1, cv2.LINE_AA)
        xv = x0 + (x1 - x0) * k / 5
        x = int(px(np.array([xv]), np.array([0.0]))[0, 0])
        cv2.putText(img, f"{xv:.0f}", (x - 8, height - bottom + 16), font, 0.4, (60, 60, 60),
                    1, cv2.LINE_AA)
    cv2.polylines(img, [px(s, ref)], False, (150, 150, 150), 1, cv2.LINE_AA)
    smooth = getattr(prof, "diameter_smooth_mm", None)
    if smooth is not None:
        cv2.polylines(img, [px(s, d)], False, (160, 190, 235), 1, cv2.LINE_AA)
        d = np.asarray(smooth, dtype=float)
    cv2.polylines(img, [px(s, d)], False, (30, 90, 200), 2, cv2.LINE_AA)
    mld_s = meas.get("mld_s_mm")
    mld = meas.get("mld_mm")
    if mld_s is not None and mld is not None:
        p = px(np.array([mld_s]), np.array([mld]))[0]
        cv2.circle(img, (int(p[0]), int(p[1])), 5, (220, 30, 30), -1, cv2.LINE_AA)
        cv2.putText(img, f"MLD {float(mld):.2f} mm", (int(p[0]) + 7, int(p[1]) + 14), font,
                    0.45, (220, 30, 30), 1, cv2.LINE_AA)
    cv2.putText(img, "diameter (mm) vs arc length (mm); grey: reference; red band: lesion",
                (left, 16), font, 0.4, (40, 40, 40), 1, cv2.LINE_AA)
    return img


class _View:
    """One angiogram as shown: the loaded run, display window, scene handles, vesselness."""

    def __init__(self, key: str, angio: Angiogram, display_name: str) -> None:
        self.key = key
        self.angio = angio
        self.display_name = display_name
        self.level, self.width = _default_window(angio.image)
        self.vesselness: object | None = None
        self.vesselness_lock = threading.Lock()
        rows, cols = angio.image.shape
        scale = IMAGE_SIZE / max(rows, cols)
        self.render_w, self.render_h = cols * scale, rows * scale
        x = (self.render_w if key == "b" else -self.render_w) / 2 + (
            IMAGE_GAP / 2 if key == "b" else -IMAGE_GAP / 2
        )
        self.position = np.array([x, 0.0, 0.0])
        self.handles: dict[str, object] = {}
        self.labels: list[object] = []

    @property
    def rows(self) -> int:
        return int(self.angio.image.shape[0])

    @property
    def cols(self) -> int:
        return int(self.angio.image.shape[1])

    def local_from_px(self, points_px: FloatArray, z: float = OVERLAY_Z) -> FloatArray:
        """Pixels (N, 2) (col, row) -> node-local points (N, 3)."""
        p = np.asarray(points_px, dtype=float).reshape(-1, 2)
        x = (p[:, 0] + 0.5) / self.cols * self.render_w - self.render_w / 2
        y = (p[:, 1] + 0.5) / self.rows * self.render_h - self.render_h / 2
        return np.column_stack([x, y, np.full(len(p), z)])

    def px_from_local(self, xy: FloatArray) -> FloatArray:
        """Node-local (x, y) -> pixel (col, row)."""
        col = (xy[0] + self.render_w / 2) / self.render_w * self.cols - 0.5
        row = (xy[1] + self.render_h / 2) / self.render_h * self.rows - 0.5
        return np.array([col, row])

    def get_vesselness(self) -> object:
        """Vesselness of the current frame, computed once (recon.centerline)."""
        from recon.centerline import compute_vesselness

        with self.vesselness_lock:
            if self.vesselness is None:
                self.vesselness = compute_vesselness(self.angio.image)
            return self.vesselness


class ViewerApp:
    """The viewer: a viser server plus the state of one image pair.

    Parameters
    ----------
    path_a, path_b : the two angiograms (A is the reference view); both None
        opens the bundled demo case (``assets/demo``).
    seeds_path : a seeds.json to start from (demo: ``assets/demo/seeds.json``).
    host, port : where to serve; port 0 picks a free port (see :attr:`port`).
    frame_a, frame_b : 0-based frames of cine runs (None: the loader's choice).
    autosave_path : where marks are autosaved; None:
        ``~/.cache/coronary3d/autosave/<pair>.json``.

    Raises
    ------
    recon.dicom_io.LoadError, recon.seeds.SeedsError : the initial files cannot be
        used (later errors appear as notifications in the page).
    """

    def __init__(
        self,
        path_a: str | None = None,
        path_b: str | None = None,
        seeds_path: str | None = None,
        host: str = "127.0.0.1",
        port: int = 8080,
        frame_a: int | None = None,
        frame_b: int | None = None,
        autosave_path: str | Path | None = None,
    ) -> None:
        if (path_a is None) != (path_b is None):
            raise ValueError("give both angiograms (A and B) or none for the demo case")
        if path_a is None:
            path_a, path_b = str(DEMO_DIR / "a.dcm"), str(DEMO_DIR / "b.dcm")
            if seeds_path is None and (DEMO_DIR / "seeds.json").is_file():
                seeds_path = str(DEMO_DIR / "seeds.json")
        self._lock = threading.RLock()
        self._autosave_arg = autosave_path
        self.notifications: list[tuple[str, str, str]] = []  # (level, title, body)
        self.last_click_ms: float = float("nan")
        self.reconstruction: object | None = None
        self.calibration: object | None = None
        self.progress_log: list[tuple[str, float]] = []
        self._tmpdir = tempfile.TemporaryDirectory(prefix="coronary3d-viewer-")
        self._busy = False

        angio_a = load_angiogram(path_a, frame=frame_a)
        angio_b = load_angiogram(path_b, frame=frame_b)
        seeds = load_seeds(seeds_path) if seeds_path is not None else None

        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.server.scene.set_up_direction("-y")
        self.server.initial_camera.position = (PANEL_SHIFT, -0.05, -1.5)
        self.server.initial_camera.look_at = (PANEL_SHIFT, -0.05, 0.0)
        self.server.initial_camera.up = (0.0, -1.0, 0.0)
        self.server.gui.configure_theme(control_width="large", show_share_button=False)
        self._build_gui()
        self._set_pair(angio_a, angio_b, Path(path_a).name, Path(path_b).name, seeds, seeds_path)

    # ================================================================ basics
    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def url(self) -> str:
        host = self.server.get_host()
        shown = "127.0.0.1" if host in ("0.0.0.0", "") else host
        return f"http://{shown}:{self.port}/"

    def stop(self) -> None:
        """Autosave and stop the server."""
        with self._lock:
            self._autosave()
        self.server.stop()
        self._tmpdir.cleanup()

    def notify(
        self, title: str, body: str, level: str = "info", client: object | None = None
    ) -> None:
        """Show a notification (to ``client``, or every connected client) and log it."""
        self.notifications.append((level, title, body))
        color = {"error": "red", "warning": "yellow", "info": "blue", "success": "green"}[level]
        clients = [client] if client is not None else list(self.server.get_clients().values())
        for c in clients:
            try:
                c.add_notification(title, body, color=color, auto_close_seconds=8.0)
            except Exception:  # a client that went away must not break the app
                log.debug("notification to a closed client", exc_info=True)

    def _guard(self, what: str, client: object | None, func: Callable[[], object]) -> object:
        """Run ``func``; user errors (ValueError) and bugs become notifications, not a dead page."""
        try:
            return func()
        except ValueError as exc:
            self.notify(f"{what} failed", str(exc).splitlines()[0], "error", client)
        except Exception as exc:
            log.error("%s: %s", what, traceback.format_exc())
            self.notify(f"{what} failed", f"internal error: {exc!r}", "error", client)
        return None

    def wait_ready(self) -> None:
        """Block until both vesselness maps (used to snap clicks) are computed."""
        for v in self.views.values():
            v.get_vesselness()

    # ================================================================ pair
    def _set_pair(
        self,
        angio_a: Angiogram,
        angio_b: Angiogram,
        name_a: str,
        name_b: str,
        seeds: Seeds | None,
        seeds_path: str | None,
    ) -> None:
        with self._lock:
            self.views = {"a": _View("a", angio_a, name_a), "b": _View("b", angio_b, name_b)}
            self.state = MarkState(angio_a.geometry, angio_b.geometry, snapper=self._snap)
            self.reconstruction = None
            self.calibration = None
            if seeds is not None:
                self.state.load_seeds(seeds)
            path = self._autosave_arg or default_autosave_path(angio_a.path, angio_b.path)
            self.autosave = Autosave(path, angio_a.path, angio_b.path)
            self.restored_autosave = self.autosave.load_into(self.state, seeds_path)
            self.state._history.clear()
            self._build_scene()
            self._refresh_gui_for_pair()
            self._clear_results()
            self._redraw_marks()
        for view in self.views.values():  # vesselness in the background, once per image
            threading.Thread(target=self._warm_vesselness, args=(view,), daemon=True).start()

    @staticmethod
    def _warm_vesselness(view: _View) -> None:
        try:
            view.get_vesselness()
        except Exception:
            log.warning("vesselness failed for %s", view.angio.path, exc_info=True)

    def open_pair(
        self,
        path_a: str,
        path_b: str,
        frame_a: int | None = None,
        frame_b: int | None = None,
        client: object | None = None,
    ) -> bool:
        """Open two other files; a bad file gives an error notification and returns False."""

        def run() -> bool:
            angio_a = load_angiogram(path_a, frame=frame_a)
            angio_b = load_angiogram(path_b, frame=frame_b)
            with self._lock:
                self._autosave()
            self._set_pair(angio_a, angio_b, Path(path_a).name, Path(path_b).name, None, None)
            self.notify("Opened", f"A: {Path(path_a).name}, B: {Path(path_b).name}", "success",
                        client)
            return True

        return bool(self._guard("Open", client, run))

    def open_upload(self, view: str, filename: str, content: bytes,
                    client: object | None = None) -> bool:
        """Replace one view by an uploaded file (kept in a private temporary folder)."""
        safe = Path(filename).name or f"upload_{view}.dcm"
        folder = Path(self._tmpdir.name) / f"{view}-{time.time_ns()}"
        folder.mkdir(parents=True)
        path = folder / safe
        path.write_bytes(content)
        other = self.views["b" if view == "a" else "a"].angio.path
        pa, pb = (str(path), other) if view == "a" else (other, str(path))
        return self.open_pair(pa, pb, client=client)

    def set_frame(self, view: str, index: int) -> None:
        """Show frame ``index`` (0-based) of a cine run; marks stay, vesselness is redone."""
        with self._lock:
            v = self.views[view]
            if index == v.angio.frame_index:
                return
            v.angio = v.angio.with_frame(int(index))
            v.vesselness = None
            self._update_image(v)
            self._refresh_info()
        threading.Thread(target=self._warm_vesselness, args=(v,), daemon=True).start()

    def set_window(self, view: str, level: float, width: float) -> None:
        with self._lock:
            v = self.views[view]
            v.level, v.width = float(level), max(float(width), 1e-3)
            self._update_image(v)

    # ================================================================ marks
    def _snap(self, view: str, raw_px: FloatArray) -> tuple[FloatArray, float | None, str | None]:
        from recon.centerline import snap_click

        try:
            vmap = self.views[view].get_vesselness()
            point, distance = snap_click(vmap, raw_px, max_distance_px=SNAP_MAX_PX)
        except ValueError as exc:
            return raw_px, None, f"not snapped, kept where clicked: {str(exc).splitlines()[0]}"
        return np.asarray(point, dtype=float), float(distance), None

    def click(self, view: str, col: float, row: float, client: object | None = None) -> Mark | None:
        """Place a mark at pixel (col, row) of view "a" or "b" in the current mode.

        Returns the mark (or None, with an error notification, for a click
        outside the image). :attr:`last_click_ms` is the server time from the
        call to the redrawn marks and epipolar line.
        """
        t0 = time.perf_counter()
        with self._lock:
            try:
                mark = self.state.click(view, float(col), float(row))
            except ValueError as exc:
                self.notify("Click ignored", str(exc), "error", client)
                return None
            self._redraw_marks()
            self.last_click_ms = (time.perf_counter() - t0) * 1e3
            if self.state.last_message:
                self.notify("Mark placed raw", f"{view.upper()}: {self.state.last_message}",
                            "warning", client)
            self._autosave()
            return mark

    def set_mode(self, mode: str) -> None:
        """One of "proximal", "waypoint", "distal", "feature"."""
        with self._lock:
            self.state.set_mode(mode)
            if self._gui["mode"].value != MODE_LABELS[mode]:
                self._gui["mode"].value = MODE_LABELS[mode]

    def new_segment(self, name: str | None = None) -> int:
        with self._lock:
            index = self.state.new_segment(name)
            self._redraw_marks()
            self._autosave()
            return index

    def select(self, mark_id: int | None) -> None:
        with self._lock:
            self.state.select(mark_id)
            self._redraw_marks()

    def undo(self) -> bool:
        with self._lock:
            done = self.state.undo()
            self._redraw_marks()
            self._autosave()
            return done

    def clear(self) -> None:
        with self._lock:
            self.state.clear()
            self._redraw_marks()
            self._autosave()

    @property
    def epipolar_segments(self) -> dict[str, FloatArray | None]:
        """Epipolar line currently drawn in each view: (2, 2) end points (col, row) or None."""
        with self._lock:
            out: dict[str, FloatArray | None] = {"a": None, "b": None}
            hit = self.state.epipolar_segment()
            if hit is not None:
                out[hit[0]] = hit[1]
            return out

    def seeds(self) -> Seeds:
        with self._lock:
            return self.state.to_seeds()

    def save_seeds(self, path: str | Path) -> None:
        save_seeds(self.seeds(), path)

    def load_seeds(self, path: str | Path, client: object | None = None) -> bool:
        """Replace the marks by a seeds.json; errors become a notification (returns False)."""

        def run() -> bool:
            seeds = load_seeds(path)
            with self._lock:
                self.state.load_seeds(seeds)
                self._redraw_marks()
                self._autosave()
            return True

        return bool(self._guard("Load seeds", client, run))

    def _autosave(self) -> None:
        try:
            self.autosave.save(self.state)
        except OSError as exc:
            log.warning("autosave to %s failed: %s", self.autosave.path, exc)

    # ================================================================ compute
    def _seeds_for_run(self) -> tuple[Seeds, int]:
        seeds = self.state.to_seeds()
        if not seeds.segments:
            missing = "; ".join(self.state.missing()[:3])
            raise ValueError(f"marks: no complete segment yet ({missing})")
        name = self.state.segment_names[self.state.current_segment]
        names = [s.name for s in seeds.segments]
        return seeds, names.index(name) if name in names else 0

    def calibrate(self, client: object | None = None) -> object | None:
        """PALM calibration of view B on the marks; returns the CalibrationResult or None."""

        def run() -> object:
            from recon.pipeline import calibrate_from_seeds

            with self._lock:
                seeds, segment = self._seeds_for_run()
                a, b = self.views["a"].angio, self.views["b"].angio
            res = calibrate_from_seeds(a, b, seeds, optimizer="palm", segment=segment)
            with self._lock:
                self.calibration = res
                self.state.set_calibrated_b(res.view_b)
                self._gui["calib_md"].content = self._calibration_markdown(res)
                self._redraw_marks()
            self.notify("Calibrated", f"error {res.error_before_px:.2f} px -> "
                        f"{res.error_after_px:.2f} px", "success", client)
            return res

        return self._guard("Calibrate", client, run)

    @staticmethod
    def _calibration_markdown(res: object) -> str:
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
        lines += [f"- ⚠ {w}" for w in getattr(res, "warnings", ())]
        return "\n".join(lines)

    def reconstruct(self, client: object | None = None) -> object | None:
        """Run recon.pipeline.reconstruct_pair on the marks; draw and tabulate the result."""
        if self._busy:
            self.notify("Busy", "a reconstruction is already running", "warning", client)
            return None
        clients = [client] if client is not None else list(self.server.get_clients().values())
        handles = []
        for c in clients:
            try:
                handles.append(c.add_notification("Reconstructing", "starting", loading=True,
                                                  with_close_button=False))
            except Exception:
                log.debug("notification failed", exc_info=True)
        self.progress_log = []

        def progress(stage: str, fraction: float) -> None:
            self.progress_log.append((stage, float(fraction)))
            self._gui["progress"].value = float(np.clip(fraction * 100.0, 0.0, 100.0))
            for h in handles:
                h.body = f"{stage} ({fraction * 100:.0f} %)"

        def run() -> object:
            from recon.pipeline import ReconstructionOptions, reconstruct_pair

            with self._lock:
                seeds, segment = self._seeds_for_run()
                view_a, view_b = self.views["a"], self.views["b"]
            options = ReconstructionOptions(matcher="match3", optimizer="palm", segment=segment)
            maps = (view_a.get_vesselness(), view_b.get_vesselness())  # cached for snapping
            rec = reconstruct_pair(view_a.angio, view_b.angio, seeds, options,
                                   progress=progress, vesselness=maps)
            with self._lock:
                self.reconstruction = rec
                self.calibration = rec.calibration
                self.state.set_calibrated_b(rec.view_b)
                self._gui["calib_md"].content = self._calibration_markdown(rec.calibration)
                self._show_reconstruction(rec)
                self._redraw_marks()
            self.notify("Reconstructed", f"{rec.centerline_3d.length_mm:.1f} mm centerline, "
                        f"{len(rec.surface.mesh.faces)} faces, "
                        f"{rec.timings_ms.get('total', 0):.0f} ms", "success", client)
            return rec

        self._busy = True
        try:
            return self._guard("Reconstruct", client, run)
        finally:
            self._busy = False
            for h in handles:
                try:
                    h.remove()
                except Exception:
                    log.debug("notification removal failed", exc_info=True)

    def export(self, kind: str) -> bytes:
        """Bytes of an output: a mesh format ("stl", "obj", "ply", "glb"),
        "centerline.csv", "report.json" or "seeds.json" (the marks; needs no reconstruction).

        Raises ValueError when there is no reconstruction yet or the kind is unknown.
        """
        import json

        if kind not in EXPORT_KINDS:
            raise ValueError(f"export: unknown kind {kind!r} (one of {', '.join(EXPORT_KINDS)})")
        if kind == "seeds.json":
            return (json.dumps(self.seeds().to_dict(), indent=2) + "\n").encode()
        rec = self.reconstruction
        if rec is None:
            raise ValueError(f"export {kind}: reconstruct first")
        from recon.pipeline import outputs_as_bytes

        fmt = kind if kind in MESH_FORMATS else "stl"
        files = outputs_as_bytes(rec, formats=(fmt,))
        return files[f"mesh.{kind}" if kind in MESH_FORMATS else kind]

    def download(self, kind: str, client: object | None = None) -> None:
        """Send an export to the browser (a file download)."""

        def run() -> None:
            data = self.export(kind)
            name = f"mesh.{kind}" if kind in MESH_FORMATS else kind
            targets = [client] if client is not None else list(self.server.get_clients().values())
            for c in targets:
                c.send_file_download(name, data, save_immediately=True)

        self._guard("Download", client, run)

    # ================================================================ scene
    def _build_scene(self) -> None:
        scene = self.server.scene
        for v in self.views.values():
            name = f"/view_{v.key}"
            v.handles["image"] = scene.add_image(
                name,
                _rgb_from_image(v.angio.image, v.level, v.width),
                v.render_w,
                v.render_h,
                position=tuple(v.position),
                format="jpeg",
                jpeg_quality=90,
                cast_shadow=False,
                receive_shadow=False,
            )
            v.handles["image"].on_click(self._make_click_callback(v.key))
            empty_pts = np.zeros((0, 3), np.float32)
            empty_seg = np.zeros((0, 2, 3), np.float32)
            v.handles["marks"] = scene.add_point_cloud(
                f"{name}/marks", empty_pts, (255, 255, 255), point_size=0.016,
                point_shape="circle", point_shading="flat")
            v.handles["selected"] = scene.add_point_cloud(
                f"{name}/selected", empty_pts, (255, 255, 255), point_size=0.028,
                point_shape="circle", point_shading="flat")
            v.handles["epipolar"] = scene.add_line_segments(
                f"{name}/epipolar", empty_seg, EPIPOLAR_COLOR, thickness=2.5,
                thickness_units="screen")
            v.handles["trace"] = scene.add_line_segments(
                f"{name}/trace", empty_seg, TRACE_COLOR, thickness=2.0, thickness_units="screen")
            v.handles["backproj"] = scene.add_line_segments(
                f"{name}/backproj", empty_seg, BACKPROJ_COLOR, thickness=2.0,
                thickness_units="screen")
            g = v.angio.geometry
            v.handles["title"] = scene.add_label(
                f"{name}/title",
                f"{v.key.upper()}: {v.display_name} — {_angle_text(g.alpha_deg, g.beta_deg)}",
                position=(-v.render_w / 2, -v.render_h / 2 - 0.02, 0.0),
                anchor="bottom-left",
            )

    def _make_click_callback(self, view: str) -> Callable:
        async def on_click(event: viser.SceneNodePointerEvent) -> None:
            px = self._ray_to_px(view, event.ray_origin, event.ray_direction)
            if px is not None:
                self.click(view, px[0], px[1], client=event.client)

        return on_click

    def _ray_to_px(self, view: str, origin: tuple, direction: tuple) -> FloatArray | None:
        """Intersect a world ray with the (unrotated) image plane -> pixel (col, row)."""
        v = self.views[view]
        o, d = np.asarray(origin, float), np.asarray(direction, float)
        if abs(d[2]) < 1e-12:
            return None
        t = (v.position[2] - o[2]) / d[2]
        hit = o + t * d - v.position
        return v.px_from_local(hit[:2])

    def px_to_world(self, view: str, col: float, row: float) -> FloatArray:
        """World (viser) position (3,) of pixel (col, row) on the image plane (for tests)."""
        v = self.views[view]
        return v.local_from_px(np.array([[col, row]]), z=0.0)[0] + v.position

    def _update_image(self, v: _View) -> None:
        v.handles["image"].image = _rgb_from_image(v.angio.image, v.level, v.width)

    def _redraw_marks(self) -> None:
        """Marks, labels, selection and the epipolar line of the selected mark."""
        st = self.state
        sel = st.selected
        epi = st.epipolar_segment()
        for v in self.views.values():
            marks = st.marks_in(v.key)
            pts = v.local_from_px(np.array([m.point_px for m in marks]).reshape(-1, 2))
            v.handles["marks"].points = pts.astype(np.float32)
            v.handles["marks"].colors = np.array(
                [KIND_COLORS[m.kind] for m in marks], np.uint8).reshape(-1, 3)
            sel_pts = (v.local_from_px(np.array([sel.point_px]), z=OVERLAY_Z / 2)
                       if sel is not None and sel.view == v.key else np.zeros((0, 3)))
            v.handles["selected"].points = sel_pts.astype(np.float32)
            for h in v.labels:
                h.remove()
            v.labels = [
                self.server.scene.add_label(
                    f"/view_{v.key}/labels/m{m.id}", st.label(m),
                    position=tuple(p + np.array([0.008, 0.008, 0.0])), anchor="top-left",
                    font_screen_scale=0.8)
                for m, p in zip(marks, pts, strict=True)
            ]
            if epi is not None and epi[0] == v.key:
                seg = v.local_from_px(epi[1], z=OVERLAY_Z * 1.5)[None]
            else:
                seg = np.zeros((0, 2, 3))
            v.handles["epipolar"].points = seg.astype(np.float32)
        self._refresh_marks_gui()

    def _clear_results(self) -> None:
        for v in self.views.values():
            v.handles["trace"].points = np.zeros((0, 2, 3), np.float32)
            v.handles["backproj"].points = np.zeros((0, 2, 3), np.float32)
        for name in ("/model",):
            try:
                self.server.scene.remove_by_name(name)
            except Exception:
                log.debug("nothing to remove at %s", name, exc_info=True)
        if hasattr(self, "_gui"):
            self._gui["results_md"].content = "No reconstruction yet."
            self._gui["calib_md"].content = (
                "Not calibrated: epipolar lines use the header geometry.\n\n"
                "Tip: landmarks spread over the image (branch points and vessel ends far "
                "from the lesion) fix view B's pose better than clicks near the lesion "
                "(`coronary3d bench calibration`, landmark rows)."
            )
            self._gui["plot"].visible = False

    def _show_reconstruction(self, rec: object) -> None:
        """Traces and back-projections on the images, mesh + 3D centerline, table, plot."""
        X = np.asarray(rec.centerline_3d.X_world, dtype=float)
        for key, cl, geom in (("a", rec.centerline_a, rec.view_a), ("b", rec.centerline_b,
                                                                    rec.view_b)):
            v = self.views[key]
            v.handles["trace"].points = _polyline_segments(
                v.local_from_px(cl.points_px, z=OVERLAY_Z * 0.8)).astype(np.float32)
            v.handles["backproj"].points = _polyline_segments(
                v.local_from_px(geom.project(X), z=OVERLAY_Z * 1.2)).astype(np.float32)
        # The model in view A's frame (x = columns, y = rows, z = away from the source),
        # so the first look at it matches view A; scaled to MODEL_SIZE, above the images.
        R = rec.view_a.R_view_from_world
        mesh = rec.surface.mesh.copy()
        V_view = np.asarray(mesh.vertices) @ R.T  # mm, view A's (u, v, d) axes
        lo, hi = V_view.min(axis=0), V_view.max(axis=0)
        scale = MODEL_SIZE / max(float(np.max((hi - lo)[:2])), 1e-6)
        image_top = -max(v.render_h for v in self.views.values()) / 2
        self.model_position = np.array([0.0, image_top - 0.12 - MODEL_SIZE / 2, 0.0])
        T = np.eye(4)
        T[:3, :3] = scale * R
        T[:3, 3] = self.model_position - scale * (lo + hi) / 2
        mesh.apply_transform(T)
        mesh.visual.face_colors = MESH_COLOR
        scene = self.server.scene
        scene.add_mesh_trimesh("/model/mesh", mesh, cast_shadow=False, receive_shadow=False)
        X_scene = (X @ R.T) * scale + T[:3, 3]
        scene.add_line_segments("/model/centerline", _polyline_segments(X_scene).astype(
            np.float32), (255, 220, 0), thickness=3.0, thickness_units="screen")
        scene.add_label("/model/title", f"3D: {rec.centerline_3d.length_mm:.1f} mm "
                        f"(view A orientation, drag to rotate)",
                        position=(-self.views["a"].render_w - IMAGE_GAP / 2,
                                  self.model_position[1] - MODEL_SIZE / 2, 0.0),
                        anchor="top-left")
        self._frame_camera_on(self.model_position, MODEL_SIZE)
        self._gui["results_md"].content = self._results_markdown(rec)
        self._gui["plot"].image = _profile_plot(rec)
        self._gui["plot"].visible = True

    def _frame_camera_on(self, centre: FloatArray, size: float) -> None:
        for c in self.server.get_clients().values():
            try:
                with c.atomic():
                    c.camera.up_direction = (0.0, -1.0, 0.0)
                    target = centre + [PANEL_SHIFT * size, 0.0, 0.0]
                    c.camera.position = tuple(target + [0.0, 0.0, -1.5 * size])
                    c.camera.look_at = tuple(target)
            except Exception:
                log.debug("camera framing failed", exc_info=True)

    def view_all(self) -> None:
        """Camera on both images and the model."""
        self._frame_camera_on(np.array([0.0, -0.62, 0.0]), 1.45)

    @staticmethod
    def _results_markdown(rec: object) -> str:
        """3D measurements, the Table-3 metrics (per-view sub-tables side by side) and timings."""
        rows = ["| measurement | value |", "| --- | --- |"]
        rows += [f"| {k} | {_fmt(v)} |" for k, v in rec.measurements.to_dict().items()]
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
            rows += [f"| {k} | " + " | ".join(_fmt(per_view[n][k]) for n in names) + " |"
                     for k in keys]
        rows += ["", "| Table 3 (both views) | value |", "| --- | --- |"]
        rows += [f"| {k} | {_fmt(v)} |" for k, v in metrics.items()]
        rows += ["", "| stage | ms |", "| --- | --- |"]
        rows += [f"| {k} | {_fmt(v)} |" for k, v in rec.timings_ms.items()]
        return "\n".join(rows)

    # ================================================================ GUI
    def _build_gui(self) -> None:
        gui = self.server.gui
        g: dict[str, object] = {}
        self._gui = g
        with gui.add_folder("Case"):
            g["info"] = gui.add_markdown("")
            g["frame_a"] = gui.add_slider("Frame A", 0, 1, 1, 0, visible=False)
            g["frame_b"] = gui.add_slider("Frame B", 0, 1, 1, 0, visible=False)
        with gui.add_folder("Open other files", expand_by_default=False):
            g["path_a"] = gui.add_text("File A", "")
            g["path_b"] = gui.add_text("File B", "")
            g["open"] = gui.add_button("Open files", icon=viser.Icon.FOLDER_OPEN)
            g["upload_a"] = gui.add_upload_button("Upload A", icon=viser.Icon.UPLOAD)
            g["upload_b"] = gui.add_upload_button("Upload B", icon=viser.Icon.UPLOAD)
        with gui.add_folder("Window / level", expand_by_default=False):
            for key in ("a", "b"):
                g[f"level_{key}"] = gui.add_slider(f"Level {key.upper()}", 0.0, 1.0, 1.0, 0.5)
                g[f"width_{key}"] = gui.add_slider(f"Width {key.upper()}", 1.0, 2.0, 1.0, 1.0)
        with gui.add_folder("Marks"):
            g["mode"] = gui.add_dropdown("Mode", [MODE_LABELS[m] for m in MODES],
                                         initial_value=MODE_LABELS["proximal"])
            g["segment"] = gui.add_dropdown("Segment", ["Segment 1"])
            g["new_segment"] = gui.add_button("New segment", icon=viser.Icon.PLUS)
            g["select"] = gui.add_dropdown("Selected mark", ["(none)"])
            g["undo"] = gui.add_button("Undo", icon=viser.Icon.ARROW_BACK_UP)
            g["clear"] = gui.add_button("Clear marks", icon=viser.Icon.TRASH, color="red")
            g["marks_md"] = gui.add_markdown("")
        with gui.add_folder("Seeds file", expand_by_default=False):
            g["seeds_path"] = gui.add_text("Seeds file", "")
            g["load_seeds"] = gui.add_button("Load seeds from path")
            g["save_seeds"] = gui.add_button("Save seeds to path")
            g["upload_seeds"] = gui.add_upload_button("Upload seeds.json", mime_type=".json")
        with gui.add_folder("Calibrate"):
            g["calibrate"] = gui.add_button("Calibrate (PALM)", icon=viser.Icon.TARGET)
            g["calib_md"] = gui.add_markdown("")
        with gui.add_folder("Reconstruct"):
            g["reconstruct"] = gui.add_button("Reconstruct", icon=viser.Icon.PLAYER_PLAY,
                                              color="green")
            g["progress"] = gui.add_progress_bar(0.0, animated=False)
            g["view_all"] = gui.add_button("Camera: images + model", icon=viser.Icon.EYE)
            g["results_md"] = gui.add_markdown("")
            g["plot"] = gui.add_image(np.full((8, 8, 3), 255, np.uint8),
                                      label="Diameter along the vessel", visible=False)
        with gui.add_folder("Export"):
            g["mesh_format"] = gui.add_dropdown("Mesh format", list(MESH_FORMATS))
            g["dl_mesh"] = gui.add_button("Download mesh", icon=viser.Icon.DOWNLOAD)
            g["dl_csv"] = gui.add_button("Download centerline.csv", icon=viser.Icon.DOWNLOAD)
            g["dl_report"] = gui.add_button("Download report.json", icon=viser.Icon.DOWNLOAD)
            g["dl_seeds"] = gui.add_button("Download seeds.json", icon=viser.Icon.DOWNLOAD)
        self._wire_gui()

    def _wire_gui(self) -> None:
        g = self._gui
        label_to_mode = {v: k for k, v in MODE_LABELS.items()}

        # The mode, segment and selection widgets mirror the state. Setting them from
        # Python fires these callbacks later on viser's event loop (client None), when
        # the value read may already be stale: only a user's change may act.
        @g["mode"].on_update
        async def _(event: viser.GuiEvent) -> None:
            if event.client is None:
                return
            with self._lock:
                self.state.set_mode(label_to_mode[g["mode"].value])

        @g["segment"].on_update
        async def _(event: viser.GuiEvent) -> None:
            if self._refreshing or event.client is None:
                return
            with self._lock:
                names = self.state.segment_names
                if g["segment"].value in names:
                    self.state.set_current_segment(names.index(g["segment"].value))

        @g["new_segment"].on_click
        async def _(event: viser.GuiEvent) -> None:
            self.new_segment()

        @g["select"].on_update
        async def _(event: viser.GuiEvent) -> None:
            if self._refreshing or event.client is None:
                return
            value = g["select"].value
            mark_id = None if value == "(none)" else int(value.split("#")[-1])
            with self._lock:
                if mark_id == self.state.selected_id:
                    return
                if mark_id is None or self.state.mark_by_id(mark_id) is not None:
                    self.select(mark_id)

        @g["undo"].on_click
        async def _(event: viser.GuiEvent) -> None:
            self.undo()

        @g["clear"].on_click
        async def _(event: viser.GuiEvent) -> None:
            self.clear()

        @g["open"].on_click
        def _(event: viser.GuiEvent) -> None:
            pa, pb = g["path_a"].value.strip(), g["path_b"].value.strip()
            self.open_pair(pa, pb, client=event.client)

        for key in ("a", "b"):
            self._wire_view_controls(key)

        @g["load_seeds"].on_click
        def _(event: viser.GuiEvent) -> None:
            self.load_seeds(g["seeds_path"].value.strip(), client=event.client)

        @g["save_seeds"].on_click
        def _(event: viser.GuiEvent) -> None:
            path = g["seeds_path"].value.strip()

            def run() -> None:
                if not path:
                    raise ValueError("save seeds: type a file path first")
                self.save_seeds(path)
                self.notify("Saved", f"seeds written to {path}", "success", event.client)

            self._guard("Save seeds", event.client, run)

        @g["upload_seeds"].on_upload
        def _(event: viser.GuiEvent) -> None:
            f = g["upload_seeds"].value
            path = Path(self._tmpdir.name) / f"seeds-{time.time_ns()}.json"
            path.write_bytes(f.content)
            self.load_seeds(path, client=event.client)

        @g["calibrate"].on_click
        def _(event: viser.GuiEvent) -> None:
            self.calibrate(client=event.client)

        @g["reconstruct"].on_click
        def _(event: viser.GuiEvent) -> None:
            g["reconstruct"].disabled = True
            try:
                self.reconstruct(client=event.client)
            finally:
                g["reconstruct"].disabled = False

        @g["view_all"].on_click
        def _(event: viser.GuiEvent) -> None:
            self.view_all()

        @g["dl_mesh"].on_click
        def _(event: viser.GuiEvent) -> None:
            self.download(g["mesh_format"].value, client=event.client)

        for button, kind in (("dl_csv", "centerline.csv"), ("dl_report", "report.json"),
                             ("dl_seeds", "seeds.json")):
            g[button].on_click(self._make_download_callback(kind))

    def _make_download_callback(self, kind: str) -> Callable:
        def on_click(event: viser.GuiEvent) -> None:
            self.download(kind, client=event.client)

        return on_click

    def _wire_view_controls(self, key: str) -> None:
        g = self._gui

        @g[f"upload_{key}"].on_upload
        def _(event: viser.GuiEvent) -> None:
            f = g[f"upload_{key}"].value
            self.open_upload(key, f.name, f.content, client=event.client)

        @g[f"frame_{key}"].on_update
        def _(event: viser.GuiEvent) -> None:
            if self._refreshing:
                return
            self._guard("Frame", event.client,
                        lambda: self.set_frame(key, int(g[f"frame_{key}"].value)))

        def window_changed(event: viser.GuiEvent) -> None:
            if self._refreshing:
                return
            self.set_window(key, g[f"level_{key}"].value, g[f"width_{key}"].value)

        g[f"level_{key}"].on_update(window_changed)
        g[f"width_{key}"].on_update(window_changed)

    _refreshing = False

    def _refresh_gui_for_pair(self) -> None:
        g = self._gui
        self._refreshing = True
        try:
            for key, v in self.views.items():
                g[f"path_{key}"].value = v.angio.path
                lo, hi = float(v.angio.image.min()), float(v.angio.image.max())
                hi = hi if hi > lo else lo + 1.0
                lvl, wid = g[f"level_{key}"], g[f"width_{key}"]
                lvl.min, lvl.max, lvl.step = lo, hi, (hi - lo) / 200
                wid.min, wid.max, wid.step = (hi - lo) / 100, (hi - lo) * 2, (hi - lo) / 200
                lvl.value, wid.value = v.level, v.width
                fr = g[f"frame_{key}"]
                if v.angio.n_frames > 1:
                    fr.max = v.angio.n_frames - 1
                    fr.value = v.angio.frame_index
                    fr.visible = True
                else:
                    fr.visible = False
            self._refresh_info()
        finally:
            self._refreshing = False

    def _refresh_info(self) -> None:
        rows = ["| | A | B |", "| --- | --- | --- |"]
        a, b = self.views["a"], self.views["b"]
        ga, gb = a.angio.geometry, b.angio.geometry
        rows.append(f"| file | {a.display_name} | {b.display_name} |")
        rows.append(f"| angles | {_angle_text(ga.alpha_deg, ga.beta_deg)} | "
                    f"{_angle_text(gb.alpha_deg, gb.beta_deg)} |")
        rows.append(f"| SID / SOD (mm) | {ga.sid_mm:.0f} / {ga.sod_mm:.0f} | "
                    f"{gb.sid_mm:.0f} / {gb.sod_mm:.0f} |")
        rows.append(f"| size | {ga.cols}×{ga.rows} | {gb.cols}×{gb.rows} |")
        rows.append(f"| frame | {a.angio.frame_index + 1}/{a.angio.n_frames} | "
                    f"{b.angio.frame_index + 1}/{b.angio.n_frames} |")
        self._gui["info"].content = "\n".join(rows)

    def _refresh_marks_gui(self) -> None:
        g = self._gui
        st = self.state
        self._refreshing = True
        try:
            g["segment"].options = tuple(st.segment_names)
            g["segment"].value = st.segment_names[st.current_segment]
            options = ["(none)"] + [f"{m.view.upper()} {st.label(m)} #{m.id}" for m in st.marks]
            g["select"].options = tuple(options)
            sel = st.selected
            g["select"].value = (options[[m.id for m in st.marks].index(sel.id) + 1]
                                 if sel is not None else "(none)")
        finally:
            self._refreshing = False
        seeds = st.to_seeds()
        lines = [f"**{len(st.marks)} marks**: {len(seeds.segments)} complete segment(s), "
                 f"{len(seeds.features)} feature pair(s)."]
        lines += [f"- {m}" for m in st.missing()[:6]]
        if st.last_message:
            lines.append(f"- ⚠ {st.last_message}")
        if np.isfinite(self.last_click_ms):
            lines.append(f"\nLast click → epipolar line: {self.last_click_ms:.1f} ms (server).")
        lines.append(f"\nAutosave: `{self.autosave.path}`")
        g["marks_md"].content = "\n".join(lines)


def run_viewer(
    path_a: str | None,
    path_b: str | None,
    seeds_path: str | None,
    host: str = "127.0.0.1",
    port: int = 8080,
    frame_a: int | None = None,
    frame_b: int | None = None,
    on_ready: Callable[[str], None] | None = None,
    autosave_path: str | Path | None = None,
    stop_event: threading.Event | None = None,
) -> None:
    """Serve the viewer until interrupted (Ctrl-C) or ``stop_event`` is set.

    ``on_ready(url)`` is called once the server listens (the CLI prints the
    URL). Both paths None opens the bundled demo case. Raises LoadError /
    SeedsError (one line) when the initial files cannot be used.
    """
    app = ViewerApp(path_a, path_b, seeds_path, host=host, port=port, frame_a=frame_a,
                    frame_b=frame_b, autosave_path=autosave_path)
    if on_ready is not None:
        on_ready(app.url)
    stop = stop_event or threading.Event()
    try:
        while not stop.wait(0.5):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        app.stop()
