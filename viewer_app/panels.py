"""The viewer's control panel: its folders put together, and the ways the app fills them.

:func:`build_panels` builds every folder of :mod:`viewer_app.folders` in order (each
folder's widgets are typed handles, wired where they are built, to the viewer's commands
:class:`viewer_app.commands.PageCommands`; this module never imports the app).
:class:`Panels` holds them; the app shows its state through its ``show_*`` methods.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import viser

from viewer_app.commands import PageCommands
from viewer_app.folders import (
    GEOMETRY_WORDS,
    CalibratePanel,
    CasePanel,
    ExportPanel,
    GeometryPanel,
    MarksPanel,
    Refreshing,
    ResultsPanel,
    SeedsPanel,
    ViewControls,
    calibrate_folder,
    case_folder,
    export_folder,
    geometry_folder,
    marks_folder,
    results_folder,
    seeds_folder,
)
from viewer_app.marks import MODE_LABELS
from viewer_app.model_colours import ffr_key_image
from viewer_app.patients import PATIENTS_DIFFER_TEXT
from viewer_app.plot import ffr_plot, profile_plot
from viewer_app.results import (
    NO_RECONSTRUCTION_TEXT,
    NOT_CALIBRATED_TEXT,
    bifurcations_markdown,
    calibration_markdown,
    clinical_markdown,
    close_views_warning,
    ffr_note,
    info_markdown,
    marks_markdown,
    results_markdown,
    warnings_markdown,
)
from viewer_app.tree_view import branch_heading, branch_names, is_tree

if TYPE_CHECKING:
    from recon.pipeline import Reconstruction
    from recon.pose.calibration import CalibrationResult
    from recon.tree import TreeReconstruction
    from viewer_app.scene import View
    from viewer_app.state import MarkState

__all__ = [
    "CalibratePanel",
    "CasePanel",
    "ExportPanel",
    "GeometryPanel",
    "MarksPanel",
    "Panels",
    "Refreshing",
    "ResultsPanel",
    "SeedsPanel",
    "ViewControls",
    "build_panels",
    "slider_range_mm",
]


STALE_RESULTS_TEXT = ("⚠ **Out of date**: these results are of earlier marks (the marks "
                      "changed since). Press **Reconstruct** for figures of the marks shown.")
STALE_CALIBRATION_TEXT = ("⚠ **Out of date**: this calibration is of earlier marks (the marks "
                          "changed since); Calibrate or Reconstruct again.")


@dataclass(frozen=True)
class Panels:
    """Every panel of the control panel, top to bottom, and the ways the app fills them."""

    case: CasePanel
    geometry: GeometryPanel
    marks: MarksPanel
    seeds: SeedsPanel
    calibrate: CalibratePanel
    results: ResultsPanel
    export: ExportPanel
    refreshing: Refreshing

    def show_pair(self, views: Mapping[str, View]) -> None:
        """File paths, window sliders (range and value) and frame sliders of a new pair."""
        with self.refreshing.during():
            for key, v in views.items():
                c = self.case.views[key]
                c.path.value = v.angio.path
                lo, hi = float(v.angio.image.min()), float(v.angio.image.max())
                hi = hi if hi > lo else lo + 1.0
                lvl, wid = c.level, c.width
                lvl.min, lvl.max, lvl.step = lo, hi, (hi - lo) / 200
                # the page prints a slider's ends: no raw float (it showed "32.99")
                wid.min = float(f"{(hi - lo) / 100:.2g}")
                wid.max, wid.step = (hi - lo) * 2, (hi - lo) / 200
                lvl.value, wid.value = v.level, v.width
                fr = c.frame
                if v.angio.n_frames > 1:
                    fr.min, fr.max = 1, v.angio.n_frames  # frame numbers, as the case table
                    fr.value = v.angio.frame_index + 1
                    fr.visible = True
                else:
                    fr.visible = False
            self.show_info(views)

    def show_geometry(self, headers: Mapping[str, Mapping[str, object]],
                      names: Mapping[str, str]) -> None:
        """Prefill the Geometry folder: each file's values (None: missing, left empty)."""
        missing = []
        for view, fields in self.geometry.fields.items():
            for key, h in fields.items():
                value = headers[view].get(key)
                if value is None:
                    missing.append(f"{view.upper()} {GEOMETRY_WORDS[key]}")
                    h.value = ""
                else:
                    h.value = f"{float(np.asarray(value, float).reshape(-1)[0]):g}"
        text = (f"A: {names['a']} · B: {names['b']}. Empty fields are missing from the file"
                f"{': ' + ', '.join(missing) if missing else ''}. A value that differs from "
                "the header's replaces it, with a warning.")
        self.geometry.note.content = text
        self.geometry.catheter_note.content = ""  # a calibration of the files shown before

    def show_info(self, views: Mapping[str, View]) -> None:
        """The case table, and the warning at the top of the Marks folder for views too
        similar to fix depth (shown before any computation)."""
        a, b = views["a"], views["b"]
        self.case.info.content = info_markdown(a.angio, b.angio, a.display_name, b.display_name)
        warning = close_views_warning(a.angio.geometry, b.angio.geometry)
        self.marks.warning.content = "" if warning is None else f"⚠ **Views too similar**: " \
            f"{warning}"
        self.marks.warning.visible = warning is not None

    def show_patients(self, waiting: bool) -> None:
        """The warning of two patients and its confirmation button at the top of the Marks
        folder while the pair waits for the confirmation, else neither."""
        self.marks.patients.content = f"⚠ {PATIENTS_DIFFER_TEXT}" if waiting else ""
        self.marks.patients.visible = self.marks.confirm_patients.visible = waiting

    def show_marks(self, st: MarkState, last_click_ms: float, autosave_path: str | Path,
                   blocked: str | None = None) -> None:
        """The guide line (``blocked``: why Reconstruct would be refused now, said in it),
        the segment and selection lists, and the marks summary."""
        panel = self.marks
        panel.guide.content = st.guide_text(blocked)
        with self.refreshing.during():
            if panel.mode.value != MODE_LABELS[st.mode]:
                panel.mode.value = MODE_LABELS[st.mode]
            current = st.segment_names[st.current_segment]
            shown = (panel.segment.value, tuple(panel.segment.options))
            if shown != (current, tuple(st.segment_names)):  # else a name being typed stays
                panel.name.value = current
            panel.segment.options = tuple(st.segment_names)
            panel.segment.value = current
            branch = self.results.branch
            if current in branch.options:
                branch.value = current
            options = ["(none)"] + [f"{m.view.upper()} {st.label(m)} #{m.id}" for m in st.marks]
            panel.select.options = tuple(options)
            sel = st.selected
            panel.select.value = (options[[m.id for m in st.marks].index(sel.id) + 1]
                                  if sel is not None else "(none)")
        panel.summary.content = marks_markdown(st, last_click_ms, autosave_path)

    def show_layout(self, layout: str) -> None:
        with self.refreshing.during():
            if self.results.layout.value != layout:
                self.results.layout.value = layout

    def show_zoom(self, text: str) -> None:
        """The zoom's note under the Show dropdown ("" hides it)."""
        self.results.zoom_note.content = text
        self.results.zoom_note.visible = bool(text)

    def show_calibration(self, res: CalibrationResult) -> None:
        self.calibrate.markdown.content = calibration_markdown(res)

    def show_progress(self, fraction: float) -> None:
        self.results.progress.value = float(np.clip(fraction * 100.0, 0.0, 100.0))

    def show_stale(self, results: bool, calibration: bool) -> None:
        """Say at the top of the Reconstruct and Calibrate folders that what they show is
        of earlier marks (the marks changed since), or hide the line."""
        for handle, stale, text in ((self.results.stale, results, STALE_RESULTS_TEXT),
                                    (self.calibrate.stale, calibration, STALE_CALIBRATION_TEXT)):
            handle.content = text if stale else ""
            handle.visible = stale

    def clear_results(self) -> None:
        """No reconstruction, not calibrated, no chart."""
        self.show_stale(False, False)
        r = self.results
        r.progress.value = 0.0
        r.clinical.content = NO_RECONSTRUCTION_TEXT
        r.markdown.content = NO_RECONSTRUCTION_TEXT
        self.calibrate.markdown.content = NOT_CALIBRATED_TEXT
        for h in (r.plot, r.lesion_start, r.lesion_end, r.reference_proximal,
                  r.reference_distal, r.branch, r.branch_note, r.bifurcations, r.warnings,
                  r.ffr_colour, r.ffr_key, r.ffr_plot, r.ffr_note):
            h.visible = False
        r.warnings.content = ""

    def show_warnings(self, result: Reconstruction | TreeReconstruction) -> None:
        """The result's warnings above its table (results.warnings_markdown), or none."""
        text = warnings_markdown(result)
        self.results.warnings.content = text
        self.results.warnings.visible = bool(text)

    def show_tree(self, result: Reconstruction | TreeReconstruction, shown: int) -> None:
        """A tree's results: the Branch dropdown (branch ``shown`` chosen), the line naming
        the branch shown and the bifurcation table; a one-segment result hides them."""
        r = self.results
        tree = is_tree(result)
        if tree:
            names = branch_names(result)
            with self.refreshing.during():
                r.branch.options = tuple(names)
                r.branch.value = names[shown]
        r.branch_note.content = branch_heading(result, shown) if tree else ""
        r.bifurcations.content = bifurcations_markdown(result) if tree else ""
        for h in (r.branch, r.branch_note, r.bifurcations):
            h.visible = tree

    def show_reconstruction(self, rec: Reconstruction) -> None:
        """The clinical table, the diameter chart with its lesion sliders, the details."""
        r = self.results
        r.markdown.content = results_markdown(rec)
        s = np.asarray(rec.profile.s_mm, dtype=float)
        m = rec.measurements
        lo, hi = slider_range_mm(s)
        with self.refreshing.during():
            for h, value in ((r.lesion_start, m.lesion_start_s_mm),
                             (r.lesion_end, m.lesion_end_s_mm),
                             (r.reference_proximal, m.lesion_start_s_mm),
                             (r.reference_distal, m.lesion_end_s_mm)):
                h.min, h.max, h.step = lo, hi, 0.1
                h.value = float(np.clip(np.round(value, 1), lo, hi))
                h.visible = True
        self.show_lesion(rec, None)
        r.plot.visible = True

    def show_ffr(self, rec: Reconstruction, available: bool, coloured: bool) -> None:
        """The FFR of the branch shown: its pullback chart with the research-use lines
        under it, or why it was not computed (no chart); the "Colour the model by FFR"
        box (ticked when ``coloured``, disabled unless the result has an FFR,
        ``available``) and the colour key while the model is coloured by FFR."""
        r = self.results
        has = getattr(rec, "ffr", None) is not None
        if has:
            r.ffr_plot.image = ffr_plot(rec, width=440, height=346)
        r.ffr_plot.visible = has
        r.ffr_note.content = ffr_note(rec)
        r.ffr_note.visible = True
        with self.refreshing.during():
            r.ffr_colour.value = coloured and available
        r.ffr_colour.disabled = not available
        r.ffr_colour.visible = True
        if coloured and available:
            r.ffr_key.image = ffr_key_image()
        r.ffr_key.visible = coloured and available

    def show_lesion(self, rec: Reconstruction, lesion: dict[str, float] | None) -> None:
        """The clinical table and the chart for the automatic or hand-set lesion ends."""
        self.results.clinical.content = clinical_markdown(rec, lesion)
        self.results.plot.image = profile_plot(rec, width=440, height=440, lesion=lesion)


def slider_range_mm(s_mm: np.ndarray) -> tuple[float, float]:
    """A lesion slider's (min, max) in mm on its 0.1 mm grid, inside the profile's arc
    length (s_mm: (M,) increasing): the page prints them as they are."""
    lo = float(np.ceil(np.round(float(s_mm[0]) * 10.0, 6)) / 10.0)
    hi = float(np.floor(np.round(float(s_mm[-1]) * 10.0, 6)) / 10.0)
    return round(lo, 1), round(max(hi, lo + 0.1), 1)


def build_panels(gui: viser.GuiApi, app: PageCommands) -> Panels:
    """Add every folder to the control panel, in order, with its callbacks."""
    refreshing = Refreshing()
    marks = marks_folder(gui, app, refreshing)  # the workflow first
    results = results_folder(gui, app, refreshing)
    calibrate = calibrate_folder(gui, app)
    case = case_folder(gui, app, refreshing)
    geometry = geometry_folder(gui, app)
    seeds = seeds_folder(gui, app)
    export = export_folder(gui, app)
    return Panels(case=case, geometry=geometry, marks=marks, seeds=seeds,
                  calibrate=calibrate, results=results, export=export, refreshing=refreshing)

