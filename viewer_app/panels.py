"""The GUI panels of the viewer: typed widget handles, built and wired in one place.

Each panel is a small dataclass whose fields are the viser handles of one
folder of the control panel; the function that builds it also wires each
widget's callback where the widget is made. Callbacks only call the viewer's
commands (:class:`viewer_app.commands.PageCommands`, which the app provides;
this module never imports the app); the app, in turn, shows its state through
the ``Panels.show_*`` methods.

Widgets that mirror the state (frame, window, segment, selected mark) are
set from Python inside :meth:`Refreshing.during`, and their callbacks then
do nothing.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import viser

from recon.io import MESH_FORMATS
from recon.trace.intensity import INTENSITY_CHOICES
from viewer_app.commands import PageCommands
from viewer_app.plot import profile_plot
from viewer_app.results import (
    NO_RECONSTRUCTION_TEXT,
    NOT_CALIBRATED_TEXT,
    bifurcations_markdown,
    calibration_markdown,
    clinical_markdown,
    close_views_warning,
    info_markdown,
    marks_markdown,
    results_markdown,
)
from viewer_app.scene import LAYOUTS
from viewer_app.state import MODE_LABELS, MODES
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
    "MarksPanel",
    "Panels",
    "Refreshing",
    "ResultsPanel",
    "SeedsPanel",
    "ViewControls",
    "build_panels",
]

VIEW_KEYS = ("a", "b")


class Refreshing:
    """Whether Python is setting widgets to mirror the state (their callbacks must not act)."""

    def __init__(self) -> None:
        self.active = False

    @contextlib.contextmanager
    def during(self) -> Iterator[None]:
        self.active = True
        try:
            yield
        finally:
            self.active = False


@dataclass(frozen=True)
class ViewControls:
    """One view's widgets, spread over three folders (Case, Open other files, Window / level)."""

    frame: viser.GuiSliderHandle  # 0-based frame of a cine run; hidden for one frame
    path: viser.GuiTextHandle
    upload: viser.GuiUploadButtonHandle
    level: viser.GuiSliderHandle
    width: viser.GuiSliderHandle
    intensity: viser.GuiDropdownHandle  # how stored values relate to attenuation


@dataclass(frozen=True)
class CasePanel:
    """The loaded pair: the case table, opening other files and the per-view controls."""

    info: viser.GuiMarkdownHandle
    open_files: viser.GuiButtonHandle
    views: dict[str, ViewControls]  # "a", "b"


@dataclass(frozen=True)
class MarksPanel:
    """Click mode, segments, the selected mark, undo / clear and the marks summary."""

    warning: viser.GuiMarkdownHandle  # about the pair (views too similar), hidden if none
    guide: viser.GuiMarkdownHandle  # what the next click in A and in B places
    mode: viser.GuiDropdownHandle
    segment: viser.GuiDropdownHandle
    name: viser.GuiTextHandle  # the current segment's name, to rename it
    rename: viser.GuiButtonHandle
    new_segment: viser.GuiButtonHandle
    new_branch: viser.GuiButtonHandle  # a branch of the current segment at the selected landmark
    select: viser.GuiDropdownHandle
    undo: viser.GuiButtonHandle
    clear: viser.GuiButtonHandle
    summary: viser.GuiMarkdownHandle


@dataclass(frozen=True)
class GeometryPanel:
    """SID, SOD and pixel spacing per file, prefilled from the header, for files that
    lack them; "Open with this geometry" (re)opens the pair with the typed values."""

    note: viser.GuiMarkdownHandle
    fields: dict[str, dict[str, viser.GuiTextHandle]]  # view -> key -> text field
    apply: viser.GuiButtonHandle
    catheter_view: viser.GuiDropdownHandle  # catheter calibration: the view, "A" or "B"
    french: viser.GuiTextHandle  # the catheter's French size
    catheter: viser.GuiButtonHandle  # the next two clicks in that view: its edges
    catheter_note: viser.GuiMarkdownHandle

    def entries(self) -> dict[str, dict[str, str]]:
        return {v: {k: str(h.value) for k, h in f.items()} for v, f in self.fields.items()}


@dataclass(frozen=True)
class SeedsPanel:
    """Loading and saving the marks as a seeds.json."""

    path: viser.GuiTextHandle
    load: viser.GuiButtonHandle
    save: viser.GuiButtonHandle
    upload: viser.GuiUploadButtonHandle


@dataclass(frozen=True)
class CalibratePanel:
    button: viser.GuiButtonHandle
    markdown: viser.GuiMarkdownHandle


@dataclass(frozen=True)
class ResultsPanel:
    """The Reconstruct folder: the button, its progress, the camera button, tables and chart."""

    reconstruct: viser.GuiButtonHandle
    progress: viser.GuiProgressBarHandle
    layout: viser.GuiDropdownHandle  # Angiograms / Angiograms + 3D / 3D model
    branch: viser.GuiDropdownHandle  # a tree's branch shown (the Segment dropdown's twin)
    branch_note: viser.GuiMarkdownHandle  # which branch the table and chart are of
    clinical: viser.GuiMarkdownHandle  # the measurements in clinical words
    plot: viser.GuiImageHandle
    lesion_start: viser.GuiSliderHandle  # lesion ends (mm along the vessel), movable
    lesion_end: viser.GuiSliderHandle
    reference_proximal: viser.GuiSliderHandle  # where the reference diameter is read
    reference_distal: viser.GuiSliderHandle
    bifurcations: viser.GuiMarkdownHandle  # a tree's bifurcation QCA
    markdown: viser.GuiMarkdownHandle  # engineering figures, in a folded folder


@dataclass(frozen=True)
class ExportPanel:
    mesh_format: viser.GuiDropdownHandle
    mesh: viser.GuiButtonHandle
    centerline_csv: viser.GuiButtonHandle
    centerline_vtp: viser.GuiButtonHandle
    report_json: viser.GuiButtonHandle
    seeds_json: viser.GuiButtonHandle


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
                    fr.max = v.angio.n_frames - 1
                    fr.value = v.angio.frame_index
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

    def show_marks(self, st: MarkState, last_click_ms: float, autosave_path: str | Path) -> None:
        """The segment and selection lists, and the marks summary."""
        panel = self.marks
        panel.guide.content = st.guide_text()
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

    def show_calibration(self, res: CalibrationResult) -> None:
        self.calibrate.markdown.content = calibration_markdown(res)

    def show_progress(self, fraction: float) -> None:
        self.results.progress.value = float(np.clip(fraction * 100.0, 0.0, 100.0))

    def clear_results(self) -> None:
        """No reconstruction, not calibrated, no chart."""
        r = self.results
        r.clinical.content = NO_RECONSTRUCTION_TEXT
        r.markdown.content = NO_RECONSTRUCTION_TEXT
        self.calibrate.markdown.content = NOT_CALIBRATED_TEXT
        for h in (r.plot, r.lesion_start, r.lesion_end, r.reference_proximal,
                  r.reference_distal, r.branch, r.branch_note, r.bifurcations):
            h.visible = False

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
    marks = _marks_panel(gui, app, refreshing)  # the workflow first
    results = _results_panel(gui, app, refreshing)
    calibrate = _calibrate_panel(gui, app)
    case = _case_panel(gui, app, refreshing)
    geometry = _geometry_panel(gui, app)
    seeds = _seeds_panel(gui, app)
    export = _export_panel(gui, app)
    return Panels(case=case, geometry=geometry, marks=marks, seeds=seeds,
                  calibrate=calibrate, results=results, export=export, refreshing=refreshing)


def _case_panel(gui: viser.GuiApi, app: PageCommands, refreshing: Refreshing) -> CasePanel:
    with gui.add_folder("Case"):
        info = gui.add_markdown("")
        frames = {key: _frame_slider(gui, app, refreshing, key) for key in VIEW_KEYS}
    with gui.add_folder("Open other files", expand_by_default=False):
        paths = {key: gui.add_text(f"File {key.upper()}", "") for key in VIEW_KEYS}
        open_files = gui.add_button("Open files", icon=viser.Icon.FOLDER_OPEN)

        @open_files.on_click
        def _(event: viser.GuiEvent) -> None:
            pa, pb = paths["a"].value.strip(), paths["b"].value.strip()
            app.open_pair(pa, pb, client=event.client)

        uploads = {key: _upload_button(gui, app, key) for key in VIEW_KEYS}
    with gui.add_folder("Window / level", expand_by_default=False):
        windows = {key: _window_sliders(gui, app, refreshing, key) for key in VIEW_KEYS}
    with gui.add_folder("Stored values", expand_by_default=False):
        gui.add_markdown(
            "How each file's pixel values relate to the X-ray attenuation, for the radius "
            "fit: *lin* (linear in intensity), *log* (linear in attenuation) or *auto* "
            "(the file's tag, else estimated; the report says which and why)."
        )
        intensities = {key: _intensity_dropdown(gui, app, key) for key in VIEW_KEYS}
    views = {
        key: ViewControls(frame=frames[key], path=paths[key], upload=uploads[key],
                          level=windows[key][0], width=windows[key][1],
                          intensity=intensities[key])
        for key in VIEW_KEYS
    }
    return CasePanel(info=info, open_files=open_files, views=views)


def _frame_slider(
    gui: viser.GuiApi, app: PageCommands, refreshing: Refreshing, key: str
) -> viser.GuiSliderHandle:
    slider = gui.add_slider(f"Frame {key.upper()}", 0, 1, 1, 0, visible=False)

    @slider.on_update
    def _(event: viser.GuiEvent) -> None:
        if refreshing.active:
            return
        app.guard("Frame", event.client, lambda: app.set_frame(key, int(slider.value)))

    return slider


def _upload_button(gui: viser.GuiApi, app: PageCommands, key: str) -> viser.GuiUploadButtonHandle:
    upload = gui.add_upload_button(f"Upload {key.upper()}", icon=viser.Icon.UPLOAD)

    @upload.on_upload
    def _(event: viser.GuiEvent) -> None:
        f = upload.value
        app.open_upload(key, f.name, f.content, client=event.client)

    return upload


def _window_sliders(
    gui: viser.GuiApi, app: PageCommands, refreshing: Refreshing, key: str
) -> tuple[viser.GuiSliderHandle, viser.GuiSliderHandle]:
    level = gui.add_slider(f"Level {key.upper()}", 0.0, 1.0, 1.0, 0.5)
    width = gui.add_slider(f"Width {key.upper()}", 1.0, 2.0, 1.0, 1.0)

    def window_changed(event: viser.GuiEvent) -> None:
        if refreshing.active:
            return
        app.set_window(key, level.value, width.value)

    level.on_update(window_changed)
    width.on_update(window_changed)
    return level, width


def _intensity_dropdown(gui: viser.GuiApi, app: PageCommands, key: str) -> viser.GuiDropdownHandle:
    dropdown = gui.add_dropdown(f"Values {key.upper()}", list(INTENSITY_CHOICES),
                                initial_value="auto")

    @dropdown.on_update
    def _(event: viser.GuiEvent) -> None:
        app.set_intensity(key, str(dropdown.value))

    return dropdown


def _marks_panel(gui: viser.GuiApi, app: PageCommands, refreshing: Refreshing) -> MarksPanel:
    label_to_mode = {v: k for k, v in MODE_LABELS.items()}
    # The mode, segment and selection widgets mirror the state. Setting them from
    # Python fires these callbacks later on viser's event loop (client None), when
    # the value read may already be stale: only a user's change may act.
    with gui.add_folder("Marks"):
        warning = gui.add_markdown("", visible=False)
        guide = gui.add_markdown("")
        mode = gui.add_dropdown("Mode", [MODE_LABELS[m] for m in MODES],
                                initial_value=MODE_LABELS["guided"])

        @mode.on_update
        async def _(event: viser.GuiEvent) -> None:
            if refreshing.active or event.client is None:
                return
            app.set_mode(label_to_mode[mode.value])

        segment = gui.add_dropdown("Segment", ["Segment 1"])

        @segment.on_update
        async def _(event: viser.GuiEvent) -> None:
            if refreshing.active or event.client is None:
                return
            app.guard("Segment", event.client, lambda: app.set_segment(segment.value))

        name = gui.add_text("Segment name", "Segment 1", hint="The current segment's name (LAD, "
                            "D1, ...): type it, then press Rename segment")
        rename = gui.add_button("Rename segment", icon=viser.Icon.PENCIL)

        @rename.on_click
        async def _(event: viser.GuiEvent) -> None:
            app.rename_segment(name.value, client=event.client)

        new_segment = gui.add_button("New segment", icon=viser.Icon.PLUS)

        @new_segment.on_click
        async def _(event: viser.GuiEvent) -> None:
            app.new_segment()

        new_branch = gui.add_button("New branch from landmark", icon=viser.Icon.GIT_BRANCH,
                                    hint="A branch of the current segment, leaving it at "
                                    "the selected landmark (clicked in A and B)")

        @new_branch.on_click
        async def _(event: viser.GuiEvent) -> None:
            app.new_branch(client=event.client)

        select = gui.add_dropdown("Selected mark", ["(none)"])

        @select.on_update
        async def _(event: viser.GuiEvent) -> None:
            if refreshing.active or event.client is None:
                return
            value = select.value
            app.select_listed(None if value == "(none)" else int(value.split("#")[-1]))

        undo = gui.add_button("Undo", icon=viser.Icon.ARROW_BACK_UP)

        @undo.on_click
        async def _(event: viser.GuiEvent) -> None:
            app.undo()

        clear = gui.add_button("Clear marks", icon=viser.Icon.TRASH, color="red")

        @clear.on_click
        async def _(event: viser.GuiEvent) -> None:
            app.clear()

        summary = gui.add_markdown("")
    return MarksPanel(warning=warning, guide=guide, mode=mode, segment=segment, name=name,
                      rename=rename, new_segment=new_segment, new_branch=new_branch,
                      select=select, undo=undo, clear=clear, summary=summary)


GEOMETRY_WORDS = {"sid_mm": "SID (mm)", "sod_mm": "SOD (mm)",
                  "pixel_spacing_mm": "pixel spacing (mm)"}


def _geometry_panel(gui: viser.GuiApi, app: PageCommands) -> GeometryPanel:
    with gui.add_folder("Geometry", expand_by_default=False):
        note = gui.add_markdown("")
        fields = {view: {key: gui.add_text(f"{view.upper()} {word}", "")
                         for key, word in GEOMETRY_WORDS.items()} for view in VIEW_KEYS}
        apply = gui.add_button("Open with this geometry", icon=viser.Icon.CHECK)
        gui.add_markdown("**Catheter calibration** (as in 2D QCA): the guiding catheter's "
                         "French size (1 F = 1/3 mm) sets the pixel spacing at its depth.")
        catheter_view = gui.add_dropdown("Catheter in", ["A", "B"], initial_value="A")
        french = gui.add_text("Catheter size (F)", "6")
        catheter = gui.add_button("Measure catheter (click its 2 edges)",
                                  icon=viser.Icon.RULER_MEASURE)
        catheter_note = gui.add_markdown("")
    panel = GeometryPanel(note=note, fields=fields, apply=apply, catheter_view=catheter_view,
                          french=french, catheter=catheter, catheter_note=catheter_note)

    @catheter.on_click
    def _(event: viser.GuiEvent) -> None:
        app.measure_catheter(str(catheter_view.value).lower(), str(french.value),
                           client=event.client)

    @apply.on_click
    def _(event: viser.GuiEvent) -> None:
        app.apply_geometry(panel.entries(), client=event.client)

    return panel


def _seeds_panel(gui: viser.GuiApi, app: PageCommands) -> SeedsPanel:
    with gui.add_folder("Seeds file", expand_by_default=False):
        path = gui.add_text("Seeds file", "")
        load = gui.add_button("Load seeds from path")

        @load.on_click
        def _(event: viser.GuiEvent) -> None:
            app.load_seeds(path.value.strip(), client=event.client)

        save = gui.add_button("Save seeds to path")

        @save.on_click
        def _(event: viser.GuiEvent) -> None:
            target = path.value.strip()

            def run() -> None:
                if not target:
                    raise ValueError("save seeds: type a file path first")
                app.save_seeds(target)
                app.notify("Saved", f"seeds written to {target}", "success", event.client)

            app.guard("Save seeds", event.client, run)

        upload = gui.add_upload_button("Upload seeds.json", mime_type=".json")

        @upload.on_upload
        def _(event: viser.GuiEvent) -> None:
            app.load_seeds_upload(upload.value.content, client=event.client)

    return SeedsPanel(path=path, load=load, save=save, upload=upload)


def _calibrate_panel(gui: viser.GuiApi, app: PageCommands) -> CalibratePanel:
    with gui.add_folder("Calibrate"):
        button = gui.add_button("Calibrate (PALM)", icon=viser.Icon.TARGET)

        @button.on_click
        def _(event: viser.GuiEvent) -> None:
            app.calibrate(client=event.client)

        markdown = gui.add_markdown("")
    return CalibratePanel(button=button, markdown=markdown)


def _results_panel(gui: viser.GuiApi, app: PageCommands, refreshing: Refreshing) -> ResultsPanel:
    with gui.add_folder("Reconstruct"):
        reconstruct = gui.add_button("Reconstruct", icon=viser.Icon.PLAYER_PLAY, color="green")

        @reconstruct.on_click
        def _(event: viser.GuiEvent) -> None:
            reconstruct.disabled = True
            try:
                app.reconstruct(client=event.client)
            finally:
                reconstruct.disabled = False

        progress = gui.add_progress_bar(0.0, animated=False)
        layout = gui.add_dropdown("Show", list(LAYOUTS), initial_value=LAYOUTS[0])

        @layout.on_update
        def _(event: viser.GuiEvent) -> None:
            if refreshing.active or event.client is None:
                return
            app.guard("Show", event.client, lambda: app.set_layout(str(layout.value)))

        branch = gui.add_dropdown("Branch", ["Segment 1"], visible=False)

        @branch.on_update
        async def _(event: viser.GuiEvent) -> None:
            if refreshing.active or event.client is None:
                return
            app.guard("Branch", event.client, lambda: app.set_segment(str(branch.value)))

        branch_note = gui.add_markdown("", visible=False)
        clinical = gui.add_markdown("")
        plot = gui.add_image(np.full((8, 8, 3), 255, np.uint8),
                             label="Diameter along the vessel", visible=False)
        lesion_start = gui.add_slider("Lesion start (mm)", 0.0, 1.0, 0.1, 0.0, visible=False)
        lesion_end = gui.add_slider("Lesion end (mm)", 0.0, 1.0, 0.1, 1.0, visible=False)
        ref_prox = gui.add_slider("Proximal reference (mm)", 0.0, 1.0, 0.1, 0.0,
                                  visible=False)
        ref_dist = gui.add_slider("Distal reference (mm)", 0.0, 1.0, 0.1, 1.0, visible=False)

        def lesion_moved(event: viser.GuiEvent) -> None:
            if refreshing.active:
                return
            app.guard("Lesion", event.client, lambda: app.set_lesion(
                lesion_start.value, lesion_end.value, (ref_prox.value, ref_dist.value)))

        for slider in (lesion_start, lesion_end, ref_prox, ref_dist):
            slider.on_update(lesion_moved)
        bifurcations = gui.add_markdown("", visible=False)
        with gui.add_folder("Details (engineering)", expand_by_default=False):
            markdown = gui.add_markdown("")
    return ResultsPanel(reconstruct=reconstruct, progress=progress, layout=layout,
                        branch=branch, branch_note=branch_note, clinical=clinical,
                        plot=plot, lesion_start=lesion_start,
                        lesion_end=lesion_end, reference_proximal=ref_prox,
                        reference_distal=ref_dist, bifurcations=bifurcations,
                        markdown=markdown)


def _export_panel(gui: viser.GuiApi, app: PageCommands) -> ExportPanel:
    with gui.add_folder("Export"):
        mesh_format = gui.add_dropdown("Mesh format", list(MESH_FORMATS))
        mesh = gui.add_button("Download mesh", icon=viser.Icon.DOWNLOAD)

        @mesh.on_click
        def _(event: viser.GuiEvent) -> None:
            app.download(mesh_format.value, client=event.client)

        buttons = [
            _download_button(gui, app, f"Download {kind}", kind)
            for kind in ("centerline.csv", "centerline.vtp", "report.json", "seeds.json")
        ]
    return ExportPanel(mesh_format=mesh_format, mesh=mesh, centerline_csv=buttons[0],
                       centerline_vtp=buttons[1], report_json=buttons[2], seeds_json=buttons[3])


def _download_button(gui: viser.GuiApi, app: PageCommands, label: str,
                     kind: str) -> viser.GuiButtonHandle:
    button = gui.add_button(label, icon=viser.Icon.DOWNLOAD)

    def on_click(event: viser.GuiEvent) -> None:
        app.download(kind, client=event.client)

    button.on_click(on_click)
    return button

