"""Catheter calibration in the page (Geometry folder): French size, two clicks across the
guiding catheter, and the pixel spacing field of that view filled (recon.trace.catheter).

While a measurement is pending the next two clicks on that view's image go here, not
to the marks. The first edge clicked is drawn as a small yellow cross, the edges found
as two short yellow ticks; the Geometry folder's note says what to do next.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from recon.trace.catheter import FRENCH_RANGE, CatheterCalibration, calibrate_from_catheter
from viewer_app.scene import OVERLAY_Z

if TYPE_CHECKING:
    import viser

    from viewer_app.commands import Guard, Notify
    from viewer_app.folders import GeometryPanel
    from viewer_app.scene import View

__all__ = ["CatheterTool"]

EDGE_COLOR = (255, 210, 0)


class CatheterTool:
    """A pending catheter measurement of one view and the last result.

    Parameters
    ----------
    scene : the page's scene (the edges are drawn over the image).
    panel : the Geometry folder (its SID / SOD fields are read, its pixel spacing field
        filled, its catheter note kept up to date).
    notify, guard : the viewer's notifications and error guard.
    """

    def __init__(self, scene: viser.SceneApi, panel: GeometryPanel, notify: Notify,
                 guard: Guard) -> None:
        self.scene, self.panel = scene, panel
        self.notify, self.guard = notify, guard
        self.pending: tuple[str, float] | None = None  # (view, French size)
        self.clicks: list[tuple[float, float]] = []
        self.result: CatheterCalibration | None = None

    @property
    def active(self) -> bool:
        return self.pending is not None

    def start(self, view: str, french_text: str, client: object | None = None) -> bool:
        """Wait for two clicks across the catheter in ``view`` ("a" or "b") of the given
        French size (text from the page); False with an error notification if unusable."""
        try:
            french = float(str(french_text).strip().rstrip("Ff").strip())
        except ValueError:
            french = float("nan")
        if not FRENCH_RANGE[0] <= french <= FRENCH_RANGE[1]:
            self.notify("Catheter", f"catheter size {french_text!r}: give the French size, "
                            f"{FRENCH_RANGE[0]:g}-{FRENCH_RANGE[1]:g} F", "error", client)
            return False
        self.pending, self.clicks = (view, french), []
        self._note(f"Waiting: click once on each edge of the {french:g} F catheter in "
                   f"**{view.upper()}**, across it (to see it larger first: **Zoom** x4 in "
                   "the Reconstruct folder, then click the catheter).")
        self.scene.remove_by_name(f"/over_{view}/catheter")
        return True

    def click(self, v: View, col: float, row: float, intensity: str,
              client: object | None = None) -> None:
        """One click of the pending measurement on view ``v`` (a click in the other view is
        refused); ``intensity`` is that view's stored-values choice (lin, log or auto)."""
        view = v.key
        want = self.pending[0] if self.pending is not None else view
        if view != want:
            self.notify("Catheter", f"the catheter is measured in {want.upper()}: click "
                            f"its edges there", "error", client)
            return
        self.clicks.append((float(col), float(row)))
        if len(self.clicks) < 2:
            self._note(f"First edge placed in **{view.upper()}** (the cross); now click the "
                       f"other edge of the {self.pending[1]:g} F catheter.")
            self._draw_first_edge(v, np.array([col, row], dtype=float))
            return
        french = self.pending[1]
        self.pending = None
        self.guard("Catheter", client, lambda: self._finish(v, french, intensity, client))

    def _finish(self, v: View, french: float, intensity: str, client: object | None) -> None:
        from recon.trace.intensity import POWER_OF, resolve_mapping

        view = v.key
        angio = v.angio
        fields = self.panel.fields[view]
        sid = _number(fields["sid_mm"].value, angio.geometry.sid_mm)
        sod = _number(fields["sod_mm"].value, angio.geometry.sod_mm)
        mapping = resolve_mapping(angio.image, angio.info.get("pixel_intensity_relationship"),
                                  intensity)
        cal = calibrate_from_catheter(angio.image, *self.clicks, french=french, sid_mm=sid,
                                      sod_mm=sod, power=POWER_OF[mapping.mapping])
        self.result = cal
        fields["pixel_spacing_mm"].value = f"{cal.pixel_spacing_mm:.4f}"
        header = angio.geometry.pixel_spacing_mm[0]
        self._note(
            f"Catheter {french:g} F ({cal.diameter_mm:.2f} mm) in {view.upper()}: "
            f"{cal.width_px:.2f} px wide (fitted), **{cal.mm_per_px_at_catheter:.4f} mm/px** "
            f"at the catheter; detector pixel **{cal.pixel_spacing_mm:.4f} mm** (× SID "
            f"{sid:.0f} / SOD {sod:.0f}: the catheter taken at the isocentre's depth; the "
            f"file opened with {header:.4f} mm). A contrast-filled catheter with a faint wall "
            "reads near its inner diameter (spacing up to ~10 % large). Press **Open with "
            "this geometry** to use it.")
        # each edge as a tick along the catheter, 1.5 widths long, so both are seen
        e0, e1 = cal.edges_px
        along = np.array([-(e1 - e0)[1], (e1 - e0)[0]]) * 0.75
        ticks = np.array([[e - along, e + along] for e in (e0, e1)])
        seg = v.local_from_px(ticks.reshape(-1, 2), z=1.5 * OVERLAY_Z).reshape(2, 2, 3).astype(
            np.float32)
        self.scene.add_line_segments(f"/over_{view}/catheter", seg, EDGE_COLOR, thickness=3.0,
                                     thickness_units="screen")
        self.notify("Catheter", f"pixel spacing {view.upper()} {cal.pixel_spacing_mm:.4f} mm "
                    "(in the Geometry folder)", "success", client)

    def _draw_first_edge(self, v: View, edge_px: NDArray[np.float64]) -> None:
        """A cross (16 image px, wider than the catheter) where the first edge was clicked."""
        arm = np.array([[-8.0, 0.0], [8.0, 0.0], [0.0, -8.0], [0.0, 8.0]]) + edge_px
        seg = v.local_from_px(arm, z=1.5 * OVERLAY_Z).reshape(2, 2, 3).astype(np.float32)
        self.scene.add_line_segments(f"/over_{v.key}/catheter", seg, EDGE_COLOR,
                                     thickness=3.0, thickness_units="screen")

    def _note(self, text: str) -> None:
        self.panel.catheter_note.content = text


def _number(text: str, fallback: float) -> float:
    """A typed number, or the fallback when the field is empty or not a number."""
    try:
        return float(str(text).strip())
    except ValueError:
        return float(fallback)
