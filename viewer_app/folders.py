"""The folders of the viewer's control panel: each folder's widgets as a typed dataclass
of viser handles, and the function that builds the folder and wires each widget's
callback where the widget is made (to :class:`viewer_app.commands.PageCommands`, the
viewer's commands; nothing here imports the app). :mod:`viewer_app.panels` puts the
folders together and fills them.

Widgets that mirror the state (frame, window, segment, selected mark) are set from
Python inside :meth:`Refreshing.during`, and their callbacks then do nothing.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import viser

from recon.io import MESH_FORMATS
from recon.io.outputs import REPORT_PDF_NAME, SR_NAME
from recon.trace.intensity import INTENSITY_CHOICES
from viewer_app.commands import PageCommands
from viewer_app.marks import MODE_LABELS, MODES
from viewer_app.scene import LAYOUTS, ZOOMS

__all__ = [
    "GEOMETRY_WORDS",
    "VIEW_KEYS",
    "CalibratePanel",
    "CasePanel",
    "ExportPanel",
    "GeometryPanel",
    "MarksPanel",
    "Refreshing",
    "ResultsPanel",
    "SeedsPanel",
    "ViewControls",
    "calibrate_folder",
    "case_folder",
    "export_folder",
    "geometry_folder",
    "marks_folder",
    "results_folder",
    "seeds_folder",
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

    frame: viser.GuiSliderHandle  # 1-based frame number of a cine run; hidden for one frame
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
    patients: viser.GuiMarkdownHandle  # files of two patients, until confirmed; hidden
    confirm_patients: viser.GuiButtonHandle  # "They are one patient's views"; hidden
    guide: viser.GuiMarkdownHandle  # what the next click in A and in B places
    mode: viser.GuiDropdownHandle
    segment: viser.GuiDropdownHandle
    name: viser.GuiTextHandle  # the current segment's name, to rename it
    rename: viser.GuiButtonHandle
    new_segment: viser.GuiButtonHandle
    new_branch: viser.GuiButtonHandle  # a branch of the current segment at the selected landmark
    select: viser.GuiDropdownHandle
    undo: viser.GuiButtonHandle
    delete: viser.GuiButtonHandle  # the selected mark
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
    stale: viser.GuiMarkdownHandle  # "out of date" when the marks changed since; hidden
    markdown: viser.GuiMarkdownHandle


@dataclass(frozen=True)
class ResultsPanel:
    """The Reconstruct folder: the button, its progress, the camera button, tables and chart."""

    reconstruct: viser.GuiButtonHandle
    progress: viser.GuiProgressBarHandle
    stale: viser.GuiMarkdownHandle  # "out of date" when the marks changed since; hidden
    layout: viser.GuiDropdownHandle  # Angiograms / Angiograms + 3D / 3D model
    zoom: viser.GuiButtonGroupHandle  # Fit / x2 / x4 / x8 at the next click on an image
    zoom_note: viser.GuiMarkdownHandle  # what the zoom waits for or shows; hidden if none
    ffr_colour: viser.GuiCheckboxHandle  # the model coloured by FFR (else by diameter)
    ffr_key: viser.GuiImageHandle  # the FFR colour key, shown while the model has them
    branch: viser.GuiDropdownHandle  # a tree's branch shown (the Segment dropdown's twin)
    branch_note: viser.GuiMarkdownHandle  # which branch the table and chart are of
    warnings: viser.GuiMarkdownHandle  # the result's warnings (report.json's), hidden if none
    clinical: viser.GuiMarkdownHandle  # the measurements in clinical words
    plot: viser.GuiImageHandle
    lesion_start: viser.GuiSliderHandle  # lesion ends (mm along the vessel), movable
    lesion_end: viser.GuiSliderHandle
    reference_proximal: viser.GuiSliderHandle  # where the reference diameter is read
    reference_distal: viser.GuiSliderHandle
    ffr_plot: viser.GuiImageHandle  # the FFR pullback of the branch shown
    ffr_note: viser.GuiMarkdownHandle  # research use (or why no FFR), under the chart
    bifurcations: viser.GuiMarkdownHandle  # a tree's bifurcation QCA
    markdown: viser.GuiMarkdownHandle  # engineering figures, in a folded folder


@dataclass(frozen=True)
class ExportPanel:
    report_pdf: viser.GuiButtonHandle  # the whole reconstruction's report (PDF)
    report_sr: viser.GuiButtonHandle  # ... and its DICOM SR
    mesh_format: viser.GuiDropdownHandle
    mesh: viser.GuiButtonHandle
    centerline_csv: viser.GuiButtonHandle
    centerline_vtp: viser.GuiButtonHandle
    report_json: viser.GuiButtonHandle
    seeds_json: viser.GuiButtonHandle



def case_folder(gui: viser.GuiApi, app: PageCommands, refreshing: Refreshing) -> CasePanel:
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
    # 1-based, as the case table and DICOM's frame numbers count (issue 46: it was 0-based)
    slider = gui.add_slider(f"Frame {key.upper()}", 1, 2, 1, 1, visible=False)

    @slider.on_update
    def _(event: viser.GuiEvent) -> None:
        if refreshing.active:
            return
        app.guard("Frame", event.client, lambda: app.set_frame(key, int(slider.value) - 1))

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


def marks_folder(gui: viser.GuiApi, app: PageCommands, refreshing: Refreshing) -> MarksPanel:
    label_to_mode = {v: k for k, v in MODE_LABELS.items()}
    # The mode, segment and selection widgets mirror the state. Setting them from
    # Python fires these callbacks later on viser's event loop (client None), when
    # the value read may already be stale: only a user's change may act.
    with gui.add_folder("Marks"):
        warning = gui.add_markdown("", visible=False)
        patients = gui.add_markdown("", visible=False)
        confirm_patients = gui.add_button("They are one patient's views", color="red",
                                          visible=False)

        @confirm_patients.on_click
        async def _(event: viser.GuiEvent) -> None:
            app.confirm_one_patient(client=event.client)

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

        delete = gui.add_button("Delete selected mark", icon=viser.Icon.ERASER,
                                hint="Delete the mark chosen under 'Selected mark' (the one "
                                "last clicked or dragged); Undo brings it back. To move a "
                                "mark, drag it on its image.")

        @delete.on_click
        async def _(event: viser.GuiEvent) -> None:
            app.delete_selected(client=event.client)

        clear = gui.add_button("Clear marks", icon=viser.Icon.TRASH, color="red")

        @clear.on_click
        async def _(event: viser.GuiEvent) -> None:
            app.clear()

        summary = gui.add_markdown("")
    return MarksPanel(warning=warning, patients=patients, confirm_patients=confirm_patients,
                      guide=guide, mode=mode, segment=segment, name=name,
                      rename=rename, new_segment=new_segment, new_branch=new_branch,
                      select=select, undo=undo, delete=delete, clear=clear, summary=summary)


GEOMETRY_WORDS = {"sid_mm": "SID (mm)", "sod_mm": "SOD (mm)",
                  "pixel_spacing_mm": "pixel spacing (mm)"}


def geometry_folder(gui: viser.GuiApi, app: PageCommands) -> GeometryPanel:
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


def seeds_folder(gui: viser.GuiApi, app: PageCommands) -> SeedsPanel:
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


def calibrate_folder(gui: viser.GuiApi, app: PageCommands) -> CalibratePanel:
    with gui.add_folder("Calibrate"):
        button = gui.add_button("Calibrate (PALM)", icon=viser.Icon.TARGET)

        @button.on_click
        def _(event: viser.GuiEvent) -> None:
            app.calibrate(client=event.client)

        stale = gui.add_markdown("", visible=False)
        markdown = gui.add_markdown("")
    return CalibratePanel(button=button, stale=stale, markdown=markdown)


def results_folder(gui: viser.GuiApi, app: PageCommands, refreshing: Refreshing) -> ResultsPanel:
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
        stale = gui.add_markdown("", visible=False)
        layout = gui.add_dropdown("Show", list(LAYOUTS), initial_value=LAYOUTS[0])

        @layout.on_update
        def _(event: viser.GuiEvent) -> None:
            if refreshing.active or event.client is None:
                return
            app.guard("Show", event.client, lambda: app.set_layout(str(layout.value)))

        zoom = gui.add_button_group(
            "Zoom", ["Fit", *(f"x{z}" for z in ZOOMS)],
            hint="x2, x4, x8: the next click on an image shows that place magnified (it "
                 "places no mark), e.g. the guiding catheter's edges; Fit: both images whole")
        zoom_note = gui.add_markdown("", visible=False)

        @zoom.on_click
        def _(event: viser.GuiEvent) -> None:
            if event.client is None:
                return
            choice = str(zoom.value)
            app.guard("Zoom", event.client, lambda: app.fit_images() if choice == "Fit"
                      else app.zoom_at_next_click(int(choice[1:])))

        ffr_colour = gui.add_checkbox(
            "Colour the model by FFR", False, visible=False,
            hint="FFR: a model estimate for research, not validated against a pressure "
                 "wire. Unticked: coloured by lumen diameter (a tree: by branch).")

        @ffr_colour.on_update
        def _(event: viser.GuiEvent) -> None:
            if refreshing.active or event.client is None:
                return
            app.guard("FFR colours", event.client,
                      lambda: app.set_ffr_colouring(bool(ffr_colour.value), event.client))

        # charts and keys as PNG: JPEG blurs their thin lines and small text
        ffr_key = gui.add_image(np.full((8, 8, 3), 255, np.uint8), format="png",
                                visible=False)
        branch = gui.add_dropdown("Branch", ["Segment 1"], visible=False)

        @branch.on_update
        async def _(event: viser.GuiEvent) -> None:
            if refreshing.active or event.client is None:
                return
            app.guard("Branch", event.client, lambda: app.set_segment(str(branch.value)))

        branch_note = gui.add_markdown("", visible=False)
        warnings = gui.add_markdown("", visible=False)
        clinical = gui.add_markdown("")
        plot = gui.add_image(np.full((8, 8, 3), 255, np.uint8), format="png",
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
        ffr_plot = gui.add_image(np.full((8, 8, 3), 255, np.uint8), format="png",
                                 label="FFR along the vessel", visible=False)
        ffr_note = gui.add_markdown("", visible=False)
        bifurcations = gui.add_markdown("", visible=False)
        with gui.add_folder("Details (engineering)", expand_by_default=False):
            markdown = gui.add_markdown("")
    return ResultsPanel(reconstruct=reconstruct, progress=progress, stale=stale, layout=layout,
                        zoom=zoom, zoom_note=zoom_note,
                        branch=branch, branch_note=branch_note, warnings=warnings,
                        clinical=clinical,
                        plot=plot, lesion_start=lesion_start,
                        lesion_end=lesion_end, reference_proximal=ref_prox,
                        reference_distal=ref_dist, ffr_colour=ffr_colour,
                        ffr_key=ffr_key, ffr_plot=ffr_plot, ffr_note=ffr_note,
                        bifurcations=bifurcations,
                        markdown=markdown)


def export_folder(gui: viser.GuiApi, app: PageCommands) -> ExportPanel:
    with gui.add_folder("Export"):
        gui.add_markdown("The report of the whole reconstruction (every segment, lesion and "
                         "bifurcation, with 95 % intervals), as `coronary3d reconstruct "
                         "--report --sr` writes it:")
        report_pdf = _download_button(gui, app, "Download report (PDF)", REPORT_PDF_NAME)
        report_sr = _download_button(gui, app, "Download DICOM SR", SR_NAME)
        mesh_format = gui.add_dropdown("Mesh format", list(MESH_FORMATS))
        mesh = gui.add_button("Download mesh", icon=viser.Icon.DOWNLOAD)

        @mesh.on_click
        def _(event: viser.GuiEvent) -> None:
            app.download(mesh_format.value, client=event.client)

        buttons = [
            _download_button(gui, app, f"Download {kind}", kind)
            for kind in ("centerline.csv", "centerline.vtp", "report.json", "seeds.json")
        ]
    return ExportPanel(report_pdf=report_pdf, report_sr=report_sr, mesh_format=mesh_format,
                       mesh=mesh, centerline_csv=buttons[0],
                       centerline_vtp=buttons[1], report_json=buttons[2], seeds_json=buttons[3])


def _download_button(gui: viser.GuiApi, app: PageCommands, label: str,
                     kind: str) -> viser.GuiButtonHandle:
    button = gui.add_button(label, icon=viser.Icon.DOWNLOAD)

    def on_click(event: viser.GuiEvent) -> None:
        app.download(kind, client=event.client)

    button.on_click(on_click)
    return button

