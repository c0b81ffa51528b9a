"""The clinician's viewer: two angiograms, marks, calibration, reconstruction, export.

One browser page served by viser. :class:`ViewerApp` owns the server and
the state of one image pair and offers the commands (open a pair, click,
mode, undo, calibrate, reconstruct, export, download, seeds, autosave);
:mod:`viewer_app.scene` draws the 3D scene, :mod:`viewer_app.panels` builds
the control panel whose callbacks call these commands. Every numerical step
goes through ``recon`` (the same code as ``coronary3d reconstruct``).
"""

from __future__ import annotations

import contextlib
import io
import logging
import re
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import viser
from numpy.typing import NDArray

from recon.errors import LoadError, OutputError
from recon.io import demo_paths, load_angiogram, load_seeds, save_seeds
from recon.seeds import Seeds
from recon.types import Angiogram
from viewer_app import opening, scene, tree_view
from viewer_app.access import PATCHED_VISER_VERSION, FileAccess, ServerGuard, guarded_serve
from viewer_app.autosave import Autosave, default_autosave_path
from viewer_app.camera import PageCameras
from viewer_app.catheter import CatheterTool
from viewer_app.editing import MarkEditing
from viewer_app.exports import EXPORT_KINDS
from viewer_app.guide import LARGE_HEADER_ERROR_PX
from viewer_app.panels import Panels, build_panels
from viewer_app.patients import PATIENTS_WAITING_TEXT, PatientPrompt
from viewer_app.results import close_views_warning
from viewer_app.runs import RunCommands
from viewer_app.scene import LAYOUTS, ModelNodes, View
from viewer_app.state import Mark, MarkState

if TYPE_CHECKING:
    from recon.io.overrides import GeometryOverrides
    from recon.pose.calibration import CalibrationResult
    from viewer_app.tree_view import Result

__all__ = ["ViewerApp", "EXPORT_KINDS"]

log = logging.getLogger(__name__)

SNAP_MAX_PX = 8.0
MAX_TOASTS = 3  # notifications on a page at once


def public_paths(text: str, private_dir: str) -> str:
    """``text`` with the viewer's private folder of uploads left out: an uploaded file is
    named by its own name (``<private>/a-123/x.dcm`` -> ``x.dcm``), an uploaded seeds
    file as such."""
    root = re.escape(str(private_dir).rstrip("/"))
    text = re.sub(root + r"/seeds-\d+\.json", "the uploaded seeds file", text)
    text = re.sub(root + r"/[ab]-\d+/", "", text)
    return text.replace(str(private_dir), "(uploads)")

FloatArray = NDArray[np.float64]


class ViewerApp(MarkEditing, RunCommands):
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
    overrides_a, overrides_b : geometry values for file A / B (``coronary3d view
        --geometry-a`` ...); a header value they replace is named in a warning.
    out_dir : the only folder "Save seeds to path" writes into (None: the
        current folder). Paths typed in the page are confined to it and to the
        folders of A, B and the seeds file (:mod:`viewer_app.access`).

    Raises
    ------
    recon.errors.CoronaryError (LoadError, SeedsError) : the initial files cannot
        be used (later errors appear as notifications in the page).
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
        overrides_a: GeometryOverrides | None = None,
        overrides_b: GeometryOverrides | None = None,
        out_dir: str | Path | None = None,
    ) -> None:
        if (path_a is None) != (path_b is None):
            raise ValueError("give both angiograms (A and B) or none for the demo case")
        if path_a is None:
            demo = demo_paths()
            path_a, path_b = str(demo["a"]), str(demo["b"])
            if seeds_path is None and demo["seeds"].is_file():
                seeds_path = str(demo["seeds"])
        self._lock = threading.RLock()
        self.intensity = {"a": "auto", "b": "auto"}  # ReconstructionOptions.intensity_a/b
        self._autosave_arg = autosave_path
        self.notifications: list[tuple[str, str, str]] = []  # (level, title, body)
        self._toasts: dict[int, list] = {}  # client id -> its notifications, oldest first
        self.last_click_ms: float = float("nan")
        self.clicks_handled = 0  # image clicks the server has finished with (marks or not)
        self.reconstruction: Result | None = None  # one segment's, or a tree's (all segments)
        self.shown_branch = 0  # index in its branches of the one the results panel shows
        self.ffr_colouring = False  # the model coloured by FFR ("Colour the model by FFR")
        self.calibration: CalibrationResult | None = None
        self.calibration_seeds: Seeds | None = None  # the marks it is of
        self.run_angios: tuple[Angiogram, Angiogram] | None = None  # the reconstruction's
        self._shown_stale = False
        self.progress_log: list[tuple[str, float]] = []
        self._tmpdir = tempfile.TemporaryDirectory(prefix="coronary3d-viewer-")
        self._busy = False
        # Reconstruct's (memory GB, CPU s), as --max-memory-gb / --max-cpu-s; None: default
        self.limits: tuple[float | None, float | None] = (None, None)
        self.layout = LAYOUTS[0]  # what the page shows: one of scene.LAYOUTS
        self.zoom: tuple[str, tuple[float, float], int] | None = None  # (view, px, factor)
        self.zoom_pending: int | None = None  # a zoom waiting for the place to look at
        self.model: ModelNodes | None = None
        self.lesion: dict[str, float] | None = None  # lesion ends set by hand (mm), if any
        self.pair_warning: str | None = None  # views too similar to fix depth

        angio_a = load_angiogram(path_a, frame=frame_a, overrides=overrides_a)
        angio_b = load_angiogram(path_b, frame=frame_b, overrides=overrides_b)
        seeds = load_seeds(seeds_path) if seeds_path is not None else None
        self.pending_pair: tuple[str, str] | None = None  # a pair waiting for its geometry
        # files of two patients (viewer_app.patients): computing waits for a confirmation
        self.patients_differ = self.patients_confirmed = False
        self.patient_prompt = PatientPrompt(lambda client: self.confirm_one_patient(client))

        self.access = FileAccess(
            [Path(p).parent for p in (path_a, path_b, seeds_path) if p is not None]
            + [Path(self._tmpdir.name)],
            out_dir if out_dir is not None else Path.cwd(),
        )
        self.server_guard = ServerGuard(host)
        # viser's start-up banner gives the address without the token: not printed
        with guarded_serve(self.server_guard), contextlib.redirect_stdout(io.StringIO()):
            self.server = viser.ViserServer(host=host, port=port, verbose=False)
        if not self.server_guard.installed:  # a viser that no longer starts servers this way
            self.server.stop()
            raise RuntimeError(f"viser {viser.__version__}: the viewer's access check could not "
                               f"be installed (written for {PATCHED_VISER_VERSION})")
        self.server_guard.port = self.server.get_port()
        self.autosave_notices: list[str] = []
        self.server.on_client_connect(self._greet)
        self._setup_page()
        self.panels: Panels = build_panels(self.server.gui, self)
        # the Geometry folder's catheter calibration
        self.catheter = CatheterTool(self.server.scene, self.panels.geometry, self.notify,
                                     self.guard)
        self._set_pair(angio_a, angio_b, Path(path_a).name, Path(path_b).name, seeds, seeds_path)

    # ================================================================ page
    def _setup_page(self) -> None:
        """Theme and the pages' cameras (viewer_app.camera)."""
        self.server.scene.set_up_direction("-y")
        self.server.gui.configure_theme(control_width="large", show_share_button=False)
        self.server.gui.main_panel.dock_right()  # the canvas is not under the panel
        self.cameras = PageCameras(self.server, self._framing, lambda client: self.set_layout(
            "3D model" if self.model is not None else "Angiograms", client=client))

    def _framing(self, layout: str | None = None) -> scene.Framing:
        if self.zoom is not None and (layout or self.layout) != "3D model":
            return scene.zoom_framing(self.views, *self.zoom)
        return scene.layout_framing(layout or self.layout, self.views,
                                    None if self.model is None else self.model.position)

    def zoom_at_next_click(self, factor: int) -> None:
        """The next click on an image frames the page on that place, ``factor`` times
        larger than in "Angiograms" (:data:`viewer_app.scene.ZOOMS`); it places no mark."""
        if factor not in scene.ZOOMS:
            raise ValueError(f"zoom must be one of {scene.ZOOMS}, got {factor!r}")
        self.zoom_pending = factor
        self.panels.show_zoom(f"Click the place to look at: it is shown x{factor} "
                              "(no mark is placed). **Fit** shows both images again.")

    def fit_images(self) -> None:
        """Back from a zoom: the current layout's framing."""
        self.zoom, self.zoom_pending = None, None
        self.panels.show_zoom("")
        self.cameras.frame_all()

    def set_layout(self, layout: str, client: object | None = None) -> None:
        """Show "Angiograms" (straight on both images), "Angiograms + 3D" or "3D model"
        (the model alone, the camera orbiting it)."""
        with self._lock:
            self.zoom, self.zoom_pending = None, None  # a layout is shown whole
            self.panels.show_zoom("")
            fr = self._framing(layout)
            self.layout = layout
            scene.set_visibility(self.views, None if self.model is None else self.model.root,
                                 fr)
            self.panels.show_layout(layout)
            self.cameras.rotation_matters = layout != "3D model"
        self.cameras.frame_all()

    # ================================================================ basics
    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def url(self) -> str:
        host = self.server.get_host()
        shown = "127.0.0.1" if host in ("0.0.0.0", "", "::") else host
        shown = f"[{shown}]" if ":" in shown else shown
        return self.server_guard.url(shown)

    def stop(self) -> None:
        """Autosave and stop the server."""
        with self._lock:
            self._autosave()
        self.server.stop()
        self._tmpdir.cleanup()

    def _greet(self, client: viser.ClientHandle) -> None:
        """A page that connects learns what happened to the autosave at start."""
        for notice in self.autosave_notices:
            self.notify("Autosave kept aside", notice, "warning", client)
        if self.pair_warning is not None:
            self.notify("Views too similar", self.pair_warning, "warning", client)
        if self.patients_differ and not self.patients_confirmed:
            self.patient_prompt.show(client)

    def notify(
        self, title: str, body: str, level: str = "info", client: object | None = None
    ) -> None:
        """Show a notification (to ``client``, or every connected client) and log it. An
        uploaded file is named by its own name, not by the private folder it is kept in;
        at most :data:`MAX_TOASTS` stay on a page (the oldest goes)."""
        body = public_paths(body, self._tmpdir.name)
        self.notifications.append((level, title, body))
        color = {"error": "red", "warning": "yellow", "info": "blue", "success": "green"}[level]
        clients = [client] if client is not None else list(self.server.get_clients().values())
        # Information and success notes go sooner (they stack over view A's title);
        # warnings and errors stay longer, to be read.
        seconds = 8.0 if level in ("error", "warning") else 4.0
        for c in clients:
            try:
                shown = self._toasts.setdefault(c.client_id, [])
                shown.append(c.add_notification(title, body, color=color,
                                                auto_close_seconds=seconds))
                while len(shown) > MAX_TOASTS:  # they piled up over view A
                    shown.pop(0).remove()
            except Exception:  # a client that went away must not break the app
                log.debug("notification to a closed client", exc_info=True)

    def guard(self, what: str, client: object | None, func: Callable[[], object]) -> object:
        """Run ``func``; user errors (ValueError) and bugs become notifications, not a dead page."""
        try:
            return func()
        except ValueError as exc:  # a refused trace's place is ringed on its view too
            self.notify(f"{what} failed", str(exc).splitlines()[0], "error", client)
            scene.draw_refusal(self.server.scene, self.views, exc)
        except Exception as exc:
            log.error("%s: %s", what, traceback.format_exc())
            self.notify(f"{what} failed", f"internal error: {exc!r}", "error", client)
        return None

    def wait_ready(self) -> None:
        """Block until both vesselness maps (used to snap clicks) are computed."""
        for v in self.views.values():
            v.get_vesselness()

    # ================================================================ pair
    def _set_pair(self, angio_a: Angiogram, angio_b: Angiogram, name_a: str, name_b: str,
                  seeds: Seeds | None, seeds_path: str | None) -> None:
        with self._lock:
            self.views = {"a": View("a", angio_a, name_a), "b": View("b", angio_b, name_b)}
            self.zoom, self.zoom_pending = None, None
            self.state = MarkState(angio_a.geometry, angio_b.geometry, snapper=self._snap,
                                   header_check_px=LARGE_HEADER_ERROR_PX)
            self.reconstruction, self.run_angios = None, None
            self.calibration, self.calibration_seeds = None, None
            self.model = None
            if seeds is not None:
                self.state.load_seeds(seeds)
            path = self._autosave_arg or default_autosave_path(angio_a.path, angio_b.path)
            self.autosave = Autosave(path, angio_a.path, angio_b.path)
            self.restored_autosave = self.autosave.load_into(self.state, seeds_path)
            if self.autosave.notice:  # kept aside: say so now and to every page that connects
                self.autosave_notices.append(self.autosave.notice)
                log.warning("autosave: %s", self.autosave.notice)
                self.notify("Autosave kept aside", self.autosave.notice, "warning")
            self.state._history.clear()
            for v in self.views.values():
                scene.add_view_nodes(self.server.scene, v, self._make_click_callback(v.key),
                                     self._make_drag_callback(v.key))
            self.panels.show_pair(self.views)
            self.patients_differ = opening.patients_differ((angio_a.path, angio_b.path))
            self.patients_confirmed = False
            self._show_patients()
            self.pair_warning = close_views_warning(angio_a.geometry, angio_b.geometry)
            if self.pair_warning is not None:  # at once, before any computation
                self.notify("Views too similar", self.pair_warning, "warning")
            self.panels.show_geometry(
                {k: v.angio.geometry.to_dict() for k, v in self.views.items()},
                {k: v.display_name for k, v in self.views.items()})
            self._clear_results()
            self._redraw_marks()
        self.set_layout("Angiograms")
        for view in self.views.values():  # vesselness in the background, once per image
            threading.Thread(target=self._warm_vesselness, args=(view,), daemon=True).start()

    def _show_patients(self) -> None:
        """While the pair's files name two patients unconfirmed: the warning and its
        button in the Marks folder and a dialog on every page; else none of them."""
        waiting = self.patients_differ and not self.patients_confirmed
        self.panels.show_patients(waiting)
        if not waiting:
            self.patient_prompt.close_all()
            return
        log.warning("the two files name different patients: computing waits for the user")
        for client in list(self.server.get_clients().values()):
            self.patient_prompt.show(client)

    def confirm_one_patient(self, client: object | None = None) -> None:
        """The clinician confirms that files A and B, which name different patients, are
        one patient's views: Calibrate and Reconstruct may go on."""
        with self._lock:
            if not self.patients_differ or self.patients_confirmed:
                return
            self.patients_confirmed = True
            self._show_patients()
            self._redraw_marks()  # the guide line no longer waits for it
        log.info("two patients' files confirmed as one patient's views by the user")
        self.notify("One patient", "confirmed: files A and B are taken as one patient's "
                    "views", "info", client)

    @staticmethod
    def _warm_vesselness(view: View) -> None:
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
        overrides_a: GeometryOverrides | None = None,
        overrides_b: GeometryOverrides | None = None,
    ) -> bool:
        """Open two other files; a bad file gives an error notification and returns False.
        A file that lacks SID, SOD or pixel spacing fills the Geometry folder with what its
        header has, to be completed there ("Open with this geometry")."""

        def run() -> bool:
            try:
                angio_a, angio_b = opening.read_pair(self.access, (path_a, path_b),
                                                     (frame_a, frame_b), (overrides_a, overrides_b))
            except LoadError as exc:
                if "missing" in str(exc) and self._offer_geometry(path_a, path_b, client):
                    raise opening.page_wording(exc) from None
                raise
            with self._lock:
                self._autosave()
            self.pending_pair = None
            # no "opened" toast: the image titles name the files (toasts cover A's title)
            self._set_pair(angio_a, angio_b, Path(path_a).name, Path(path_b).name, None, None)
            log.info("opened a new pair")
            return True

        return bool(self.guard("Open", client, run))

    def _offer_geometry(self, path_a: str, path_b: str, client: object | None) -> bool:
        """Fill the Geometry folder from the two files' headers (missing values empty);
        False when a file cannot be read at all (the error notification says why)."""
        headers = opening.header_geometries((path_a, path_b))
        if headers is None:
            return False
        self.pending_pair = (path_a, path_b)
        self.panels.show_geometry(headers, {k: Path(p).name for k, p in
                                            (("a", path_a), ("b", path_b))})
        self.notify("Geometry needed", "enter the missing SID, SOD or pixel spacing under "
                    "Geometry, then press 'Open with this geometry'", "warning", client)
        return True

    def apply_geometry(self, entries: dict[str, dict[str, str]],
                       client: object | None = None) -> bool:
        """Open the pending pair (or reopen the current one) with typed geometry values
        (view -> key -> text, "" keeps the header's); a replaced header value is named in
        a warning."""

        def run() -> bool:
            pair = self.pending_pair or (self.views["a"].angio.path,
                                         self.views["b"].angio.path)
            overrides, warnings = opening.typed_overrides(pair, entries)
            ok = self.open_pair(pair[0], pair[1], client=client, overrides_a=overrides["a"],
                                overrides_b=overrides["b"])
            for w in warnings if ok else ():
                self.notify("Header value replaced", w, "warning", client)
            return ok

        return bool(self.guard("Geometry", client, run))

    def open_upload(self, view: str, filename: str, content: bytes,
                    client: object | None = None) -> bool:
        """Replace one view by an uploaded file (kept in a private temporary folder)."""
        path = opening.keep_upload(Path(self._tmpdir.name), view, filename, content)
        other = self.views["b" if view == "a" else "a"].angio.path
        pa, pb = (str(path), other) if view == "a" else (other, str(path))
        return self.open_pair(pa, pb, client=client)

    def measure_catheter(self, view: str, french_text: str,
                         client: object | None = None) -> bool:
        """The next two clicks in ``view`` measure the guiding catheter of the French size
        typed (:class:`viewer_app.catheter.CatheterTool`)."""
        return self.catheter.start(view, french_text, client=client)

    def set_frame(self, view: str, index: int) -> None:
        """Show frame ``index`` (0-based) of a cine run; marks stay, vesselness is redone."""
        with self._lock:
            v = self.views[view]
            if index == v.angio.frame_index:
                return
            v.angio = v.angio.with_frame(int(index))
            v.vesselness = None
            scene.update_image(v)
            self.panels.show_info(self.views)
            self._show_staleness()  # results of another frame are out of date
        threading.Thread(target=self._warm_vesselness, args=(v,), daemon=True).start()

    def set_intensity(self, view: str, choice: str) -> None:
        """How view ``view``'s stored values are read by the next Reconstruct (lin/log/auto)."""
        from recon.trace.intensity import INTENSITY_CHOICES

        if choice not in INTENSITY_CHOICES:
            raise ValueError(f"intensity must be one of {', '.join(INTENSITY_CHOICES)}")
        with self._lock:
            self.intensity[view] = choice

    def set_window(self, view: str, level: float, width: float) -> None:
        with self._lock:
            v = self.views[view]
            v.level, v.width = float(level), max(float(width), 1e-3)
            scene.update_image(v)

    # ================================================================ marks
    def _snap(self, view: str, raw_px: FloatArray) -> tuple[FloatArray, float | None, str | None]:
        from recon.trace.centerline import snap_click

        try:
            vmap = self.views[view].get_vesselness()
            point, distance = snap_click(vmap, raw_px, max_distance_px=SNAP_MAX_PX)
        except ValueError as exc:
            return raw_px, None, f"not snapped, kept where clicked: {str(exc).splitlines()[0]}"
        return np.asarray(point, dtype=float), float(distance), None

    def _make_click_callback(self, view: str) -> Callable:
        async def on_click(event: viser.SceneNodePointerEvent) -> None:
            px = scene.ray_to_px(self.views[view], event.ray_origin, event.ray_direction)
            if px is not None:
                self.click(view, px[0], px[1], client=event.client)

        return on_click

    def click(self, view: str, col: float, row: float, client: object | None = None) -> Mark | None:
        """Place a mark at pixel (col, row) of view "a" or "b" in the current mode.

        Returns the mark (or None, with an error notification, for a click
        outside the image). :attr:`last_click_ms` is the server time from the
        call to the redrawn marks and epipolar line.
        """
        try:
            return self._click(view, col, row, client)
        finally:
            self.clicks_handled += 1

    def _click(self, view: str, col: float, row: float, client: object | None) -> Mark | None:
        if self.zoom_pending is not None:  # the place to zoom on, not a mark
            self.zoom, self.zoom_pending = (view, (float(col), float(row)),
                                            self.zoom_pending), None
            self.panels.show_zoom(f"Showing {view.upper()} x{self.zoom[2]} around "
                                  f"({col:.0f}, {row:.0f}); clicks place marks again. "
                                  "**Fit** shows both images.")
            self.cameras.frame_all()
            return None
        if self.catheter.active:  # two clicks across the catheter, not marks
            self.catheter.click(self.views[view], col, row, self.intensity[view], client)
            return None
        t0 = time.perf_counter()
        with self._lock:
            try:
                mark = self.state.click(view, float(col), float(row))
            except ValueError as exc:
                self.notify("Click ignored", str(exc), "error", client)
                return None
            doubt = self.state.pairing_doubt(mark)
            if doubt is not None:  # shown in the marks panel and said at once
                self.state.last_message = doubt
                self.notify("Check the landmark pair", doubt, "warning", client)
            self._redraw_marks()
            self.last_click_ms = (time.perf_counter() - t0) * 1e3
            if self.state.last_message:  # shown in the marks panel, not as a toast over A
                log.info("mark placed raw in %s: %s", view.upper(), self.state.last_message)
            self._autosave()
            return mark

    def set_mode(self, mode: str) -> None:
        """One of "guided", "proximal", "waypoint", "distal", "feature"."""
        with self._lock:
            self.state.set_mode(mode)
            self._redraw_marks()

    def set_segment(self, name: str) -> None:
        """Make the segment called ``name`` the current one (an unknown name is ignored);
        after a tree's Reconstruct its branch's table, chart and marks are shown."""
        with self._lock:
            names = self.state.segment_names
            if name in names:
                self.state.set_current_segment(names.index(name))
                self._redraw_marks()
            rec = self.reconstruction
            shown = tree_view.branch_names(rec) if tree_view.is_tree(rec) else []
            if self.model is not None and name in shown:
                self.shown_branch, self.lesion = shown.index(name), None
                self._show_branch(rec, self.shown_branch)

    def _edit_marks(self, what: str, client: object | None, change: Callable[[], object]
                    ) -> object:
        """``change`` (an edit of ``self.state``) under the lock, then the marks redrawn and
        autosaved (a Rename or its Undo also renames the segment in the results shown); its
        value, or None with a notification when it refuses (guard)."""

        def run() -> object:
            with self._lock:
                before = list(self.state.segment_names)
                value = change()
                rec = None if self.reconstruction is None or what not in ("Rename", "Undo") \
                    else tree_view.renamed(self.reconstruction, before, self.state.segment_names)
                if rec is not None and self.model is not None:
                    self.reconstruction = rec
                    self._show_branch(rec, self.shown_branch, tree_view.is_tree(rec))
                self._redraw_marks()
                self._autosave()
                return value

        return self.guard(what, client, run)

    def new_segment(self, name: str | None = None) -> int | None:
        return self._edit_marks("New segment", None, lambda: self.state.new_segment(name))

    def new_branch(self, client: object | None = None) -> int | None:
        """A branch of the current segment leaving it at the selected landmark (state's
        ``new_branch``); its index, or None with a notification saying what to click."""
        return self._edit_marks("New branch", client, self.state.new_branch)

    def rename_segment(self, name: str, client: object | None = None) -> str | None:
        """Rename the current segment (state's ``rename_segment``); the name kept, or None
        with a notification saying what is wrong with ``name``."""
        return self._edit_marks("Rename", client, lambda: self.state.rename_segment(name))

    def select(self, mark_id: int | None) -> None:
        with self._lock:
            self.state.select(mark_id)
            self._redraw_marks()

    def select_listed(self, mark_id: int | None) -> None:
        """Select from the panel's list: nothing happens if already selected or if it is gone."""
        with self._lock:
            if mark_id == self.state.selected_id:
                return
            if mark_id is None or self.state.mark_by_id(mark_id) is not None:
                self.select(mark_id)

    def undo(self) -> bool:
        return bool(self._edit_marks("Undo", None, self.state.undo))

    def clear(self) -> None:
        """Remove every mark (undoable) and every result of them: nothing of an earlier
        reconstruction or calibration stays on the page."""
        def change() -> None:
            self.state.clear()
            self._drop_results()

        self._edit_marks("Clear marks", None, change)

    @property
    def epipolar_segments(self) -> dict[str, FloatArray | None]:
        """Epipolar line currently drawn in each view: (2, 2) end points (col, row) or None."""
        with self._lock:
            out: dict[str, FloatArray | None] = {"a": None, "b": None}
            hit = self.state.epipolar_segment()
            if hit is not None:
                out[hit[0]] = hit[1]
            return out

    def _redraw_marks(self) -> None:
        """Marks, labels, selection and epipolar line in the scene; the marks panel;
        results of earlier marks said to be out of date."""
        scene.draw_marks(self.server.scene, self.views, self.state)
        waiting = self.patients_differ and not self.patients_confirmed
        self.panels.show_marks(self.state, self.last_click_ms, self.autosave.path,
                               PATIENTS_WAITING_TEXT if waiting else None)
        self._show_staleness()

    # ================================================================ seeds
    def seeds(self) -> Seeds:
        with self._lock:
            return self.state.to_seeds()

    def save_seeds(self, path: str | Path) -> Path:
        """Write the marks as seeds.json inside the output folder; returns the path written.

        Raises ValueError for a path outside the output folder."""
        target = self.access.writable(path, "seeds file")
        save_seeds(self.seeds(), target)
        return target

    def load_seeds(self, path: str | Path, client: object | None = None) -> bool:
        """Replace the marks by a seeds.json; errors become a notification (returns False)."""

        def run() -> bool:
            seeds = load_seeds(self.access.readable(path, "seeds file"))
            with self._lock:
                self.state.load_seeds(seeds)
                self._redraw_marks()
                self._autosave()
                scene.draw_refusal(self.server.scene, self.views, None)
            return True

        return bool(self.guard("Load seeds", client, run))

    def load_seeds_upload(self, content: bytes, client: object | None = None) -> bool:
        """Replace the marks by an uploaded seeds.json (kept in a private temporary folder)."""
        path = Path(self._tmpdir.name) / f"seeds-{time.time_ns()}.json"
        path.write_bytes(content)
        return self.load_seeds(path, client=client)

    def _autosave(self) -> None:
        try:
            self.autosave.save(self.state)
        except OutputError as exc:
            log.warning("autosave failed: %s", exc)
