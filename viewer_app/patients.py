"""Two files of two patients: the page stops and asks before anything is computed.

When the two files opened name different patients (their PatientID differ,
:func:`recon.io.patients.patient_check`), the pair is
shown but Calibrate and Reconstruct refuse until the clinician confirms, on the page,
that they are one patient's views (an anonymised copy, say). Every page shows a dialog
saying so, with the confirmation; the Marks folder keeps the warning and its button.
Neither the patients' names nor their IDs are shown or logged: only that they differ.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import viser

__all__ = ["CONFIRM_LABEL", "PATIENTS_DIFFER_TEXT", "PATIENTS_WAITING_TEXT", "PatientPrompt"]

log = logging.getLogger(__name__)

PATIENTS_DIFFER_TEXT = (
    "Files A and B name **different patients** (their patient IDs differ). Two views of "
    "one patient are needed: a reconstruction from two patients' images is meaningless. "
    "Open other files, or confirm that both are this patient's views (an anonymised copy, "
    "say); until then Calibrate and Reconstruct are refused.")
CONFIRM_LABEL = "They are one patient's views"
#: What the guide line says instead of "press Reconstruct" until then.
PATIENTS_WAITING_TEXT = (f"files A and B name different patients: press **{CONFIRM_LABEL}** "
                         "above if they are, or open two views of one patient")


class PatientPrompt:
    """The dialog of each page while a pair of two patients waits for a confirmation.

    on_confirm : called with the client when a page's confirm button is pressed.
    """

    def __init__(self, on_confirm: Callable[[object | None], None]) -> None:
        self.on_confirm = on_confirm
        self._modals: dict[int, viser.GuiModalHandle] = {}

    def show(self, client: viser.ClientHandle) -> None:
        """The dialog on one page (once)."""
        if client.client_id in self._modals:
            return
        try:
            with client.gui.add_modal("Two patients?") as modal:
                client.gui.add_markdown(PATIENTS_DIFFER_TEXT)
                # the safe choice first (it has the focus)
                close = client.gui.add_button("Close (Reconstruct stays refused)")
                confirm = client.gui.add_button(CONFIRM_LABEL, color="red")
        except Exception:  # a page that went away
            log.debug("patient dialog for a closed client", exc_info=True)
            return
        self._modals[client.client_id] = modal

        @confirm.on_click
        def _(event: viser.GuiEvent) -> None:
            self.on_confirm(event.client)

        @close.on_click
        def _(event: viser.GuiEvent) -> None:
            self.close(client.client_id)

    def close(self, client_id: int) -> None:
        modal = self._modals.pop(client_id, None)
        if modal is not None and not modal.closed:
            try:
                modal.close()
            except Exception:
                log.debug("closing a patient dialog", exc_info=True)

    def close_all(self) -> None:
        for client_id in list(self._modals):
            self.close(client_id)
