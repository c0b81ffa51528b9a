"""The viewer's commands that compute and give results: Calibrate, Reconstruct, the
results shown (and when they are out of date), the lesion ends set by hand, downloads.

:class:`RunCommands` is a part of :class:`viewer_app.app.ViewerApp` (its base class),
kept in its own module; it works on the app's state, declared below, and never imports
the app.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING

from viewer_app import scene, tree_view
from viewer_app.exports import export_bytes, export_name
from viewer_app.progress import loading_notes
from viewer_app.results import calibration_doubts

if TYPE_CHECKING:
    from collections.abc import Callable

    import viser

    from recon.pipeline import Reconstruction
    from recon.pose.calibration import CalibrationResult
    from recon.seeds import Seeds
    from recon.types import Angiogram
    from viewer_app.commands import Guard, Notify
    from viewer_app.panels import Panels
    from viewer_app.scene import ModelNodes, View
    from viewer_app.state import MarkState
    from viewer_app.tree_view import Result

__all__ = ["RunCommands"]


class RunCommands:
    """Calibrate, Reconstruct, the results panel and scene, lesion ends, downloads."""

    # the app's state these commands use (set by ViewerApp)
    server: viser.ViserServer
    views: dict[str, View]
    state: MarkState
    panels: Panels
    intensity: dict[str, str]
    limits: tuple[float | None, float | None]
    reconstruction: Result | None
    calibration: CalibrationResult | None
    calibration_seeds: Seeds | None  # the marks the calibration shown is of
    run_angios: tuple[Angiogram, Angiogram] | None  # the frames the reconstruction is of
    _shown_stale: bool  # whether the page marks the results as out of date
    model: ModelNodes | None
    lesion: dict[str, float] | None
    shown_branch: int
    ffr_colouring: bool  # the model coloured by FFR (the page's box), kept across runs
    progress_log: list[tuple[str, float]]
    _busy: bool
    patients_differ: bool  # files A and B name different patients ...
    patients_confirmed: bool  # ... and the clinician confirmed them as one patient's
    _lock: threading.RLock

    # ... and the app's services (methods of ViewerApp)
    notify: Notify
    guard: Guard
    set_layout: Callable[..., None]
    seeds: Callable[[], Seeds]
    _redraw_marks: Callable[[], None]

    def calibrate(self, client: object | None = None) -> CalibrationResult | None:
        """PALM calibration of view B on the marks; returns the CalibrationResult or None."""

        def run() -> CalibrationResult:
            from recon.pipeline import calibrate_from_seeds

            self._refuse_two_patients()
            with self._lock:
                seeds, segment = tree_view.seeds_for_run(self.state)
                a, b = self.views["a"].angio, self.views["b"].angio
            maps = (self.views["a"].get_vesselness(), self.views["b"].get_vesselness())
            # The same traced ends as Reconstruct's calibration step: the same figures.
            res = calibrate_from_seeds(a, b, seeds, optimizer="palm", segment=segment,
                                       vesselness=maps,
                                       intensity=(self.intensity["a"], self.intensity["b"]))
            with self._lock:
                self.calibration, self.calibration_seeds = res, seeds
                self.state.set_calibrated_b(res.view_b)
                self.panels.show_calibration(res)
                self._redraw_marks()
            doubts = calibration_doubts(res)
            self.notify("Calibrated" if not doubts else "Calibration doubtful",
                        f"error {res.error_before_px:.2f} px -> {res.error_after_px:.2f} px"
                        + "".join(f"; {d}" for d in doubts), "warning" if doubts else "success",
                        client)
            return res

        return self.guard("Calibrate", client, run)

    def reconstruct(self, client: object | None = None) -> Result | None:
        """Reconstruct the marks in a child process, under ``self.limits``
        (recon.io.isolated): the current segment if one segment is complete, else every
        complete segment as one tree (recon.tree); draw and tabulate the result."""
        if self._busy:
            self.notify("Busy", "a reconstruction is already running", "warning", client)
            return None
        clients = [client] if client is not None else list(self.server.get_clients().values())
        self.progress_log = []
        handles: list = []

        def progress(stage: str, fraction: float) -> None:
            self.progress_log.append((stage, float(fraction)))
            self.panels.show_progress(fraction)
            for h in handles:
                h.body = f"{stage} ({fraction * 100:.0f} %)"

        def run() -> Result:
            self._refuse_two_patients()
            with self._lock:
                seeds, segment = tree_view.seeds_for_run(self.state)
                view_a, view_b = self.views["a"], self.views["b"]
                angios = (view_a.angio, view_b.angio)  # the frames this run is of
            try:
                rec = tree_view.run_reconstruction(view_a, view_b, seeds, segment,
                                                   self.intensity, self.limits, progress)
            except Exception:  # nothing of an earlier run stays shown as if it were this one's
                with self._lock:
                    self._drop_results(keep_calibration=True)
                raise
            with self._lock:
                self.reconstruction, self.run_angios = rec, angios
                self.calibration, self.calibration_seeds = rec.calibration, rec.seeds
                self.state.set_calibrated_b(tree_view.branches_of(rec)[0].view_b)
                self.state.select(None)  # no guide line across the results
                self.panels.show_calibration(rec.calibration)
                self._show_reconstruction(rec)
                self._redraw_marks()
            doubts = calibration_doubts(rec.calibration)
            if doubts:  # the figures rest on a calibration that does not fit the clicks
                self.notify("Reconstructed: check the landmarks", "; ".join(doubts), "warning",
                            client)
            else:
                self.notify("Reconstructed", tree_view.summary_text(rec), "success", client)
            return rec

        self._busy = True
        try:
            with loading_notes(clients, "Reconstructing") as notes:
                handles += notes
                return self.guard("Reconstruct", client, run)
        finally:
            self._busy = False

    def _refuse_two_patients(self) -> None:
        """Raise ValueError while files A and B name different patients unconfirmed."""
        if self.patients_differ and not self.patients_confirmed:
            raise ValueError("files A and B name different patients: open two views of one "
                             "patient, or confirm under Marks that they are one patient's")

    def _clear_results(self) -> None:
        scene.clear_results(self.server.scene, self.views)
        tree_view.draw_out_of_date(self.server.scene, self.views, None, False)
        self._shown_stale = False
        self.model = None
        self.lesion = None
        self.panels.clear_results()

    def _drop_results(self, keep_calibration: bool = False) -> None:
        """Remove every result from the page: the model, traces, MLD and lesion marks,
        off-vessel tags, tables and chart, and the calibration (its figures and warnings;
        view B back to its header geometry) unless ``keep_calibration`` and it is of the
        marks shown. After Clear marks and after a failed Reconstruct."""
        current = keep_calibration and not self._calibration_stale()
        self.reconstruction, self.run_angios = None, None
        self._clear_results()
        if current and self.calibration is not None:
            self.panels.show_calibration(self.calibration)
        else:
            self.calibration, self.calibration_seeds = None, None
            self.state.set_calibrated_b(None)
        self.set_layout("Angiograms")

    def _calibration_stale(self) -> bool:
        seeds = self.calibration_seeds
        return seeds is not None and tree_view.marks_key(seeds) != tree_view.marks_key(
            self.state.to_seeds())

    def _show_staleness(self) -> None:
        """Mark the results and the calibration shown as out of date when the marks
        changed after them (in the panels, over the images and beside the model), or
        remove the marking when they are of the marks shown again (an Undo)."""
        rec = self.reconstruction
        stale = rec is not None and (tree_view.marks_key(rec.seeds) != tree_view.marks_key(
            self.state.to_seeds()) or self.run_angios != (self.views["a"].angio,
                                                          self.views["b"].angio))
        self.panels.show_stale(stale, self._calibration_stale())
        if stale != self._shown_stale:
            tree_view.draw_out_of_date(self.server.scene, self.views, self.model, stale)
            self._shown_stale = stale

    def _show_reconstruction(self, rec: Result) -> None:
        """Traces, back-projections and lesion marks on the images, the coloured mesh (a
        tree's: each branch in its colour, the current segment's shown), the results
        table and the profile; the page shows the angiograms and the model."""
        current = self.state.segment_names[self.state.current_segment]
        self.model, self.shown_branch = tree_view.draw_result(
            self.server.scene, self.views, rec, current, self.ffr_colouring)
        self._show_branch(rec, self.shown_branch, redraw=False)
        self.lesion = None
        self.set_layout("Angiograms + 3D")

    def _show_branch(self, rec: Result, index: int, redraw: bool = True) -> None:
        """The results panel on branch ``index`` (its table, chart and lesion sliders; a
        tree's branch line and bifurcations) and, with ``redraw``, that branch highlighted
        on the images and the model."""
        if redraw:
            tree_view.highlight_branch(self.server.scene, self.views, rec, self.model, index,
                                       self.ffr_colouring)
        branch = tree_view.branches_of(rec)[index]
        self.panels.show_reconstruction(branch)
        self.panels.show_ffr(branch, tree_view.has_ffr(rec), self.ffr_colouring)
        self.panels.show_tree(rec, index)
        self.panels.show_warnings(rec)  # the whole result's (a rename renames them too)

    def set_ffr_colouring(self, on: bool, client: object | None = None) -> bool:
        """Colour the model by FFR (``on``: each vertex the FFR of its nearest centerline
        point, each branch's own; a model estimate for research) or as first drawn (a
        segment by diameter, a tree by branch); the choice holds for later Reconstructs.
        Returns whether the model shown is coloured by FFR (False without a model or an
        FFR)."""
        with self._lock:
            self.ffr_colouring = bool(on)
            rec = self.reconstruction
            if rec is None or self.model is None:
                return False
            shown = tree_view.paint_model(self.server.scene, rec, self.model,
                                          self.shown_branch, self.ffr_colouring)
            self.panels.show_ffr(tree_view.branches_of(rec)[self.shown_branch],
                                 tree_view.has_ffr(rec), self.ffr_colouring)
            return shown

    @property
    def branch(self) -> Reconstruction | None:
        """The reconstruction the results panel shows: the one segment's, or the tree's
        branch chosen under Segment (None before any Reconstruct)."""
        rec = self.reconstruction
        return None if rec is None else tree_view.branches_of(rec)[self.shown_branch]

    def set_lesion(self, start_mm: float, end_mm: float,
                   reference_mm: tuple[float, float] | None = None) -> dict[str, float]:
        """Lesion ends (and reference sites, default the ends) set by the clinician (mm
        along the vessel): the measurements, chart and MLD / lesion marks follow."""
        from viewer_app.results import lesion_measurements

        with self._lock:
            rec = self.branch
            if rec is None or self.model is None:
                raise ValueError("lesion: reconstruct first")
            lesion = lesion_measurements(rec.profile, start_mm, end_mm, reference_mm)
            self.lesion = lesion
            self.panels.show_lesion(rec, lesion)
            marks = {"MLD": lesion["mld_s_mm"], "lesion start": lesion["lesion_start_s_mm"],
                     "lesion end": lesion["lesion_end_s_mm"]}
            scene.draw_lesion_marks(self.server.scene, self.views, rec, self.model, marks,
                                    lesion["mld_mm"])
            return lesion

    # ================================================================ export
    def export(self, kind: str) -> bytes:
        """Bytes of an output (:func:`viewer_app.exports.export_bytes`) of the
        reconstruction shown, whose inputs are the angiograms it was made from."""
        return export_bytes(kind, self.reconstruction, self.seeds(), self.run_angios)

    def download(self, kind: str, client: object | None = None) -> None:
        """Send an export to the browser (a file download)."""

        def run() -> None:
            data, name = self.export(kind), export_name(kind)
            targets = [client] if client is not None else list(self.server.get_clients().values())
            for c in targets:
                c.send_file_download(name, data, save_immediately=True)

        self.guard("Download", client, run)

