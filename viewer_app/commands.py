"""What the page's widgets may ask of the viewer: the commands behind the panels.

:class:`PageCommands` is the typed list of the viewer's commands that the panels'
callbacks call (open files, click modes, segments, undo, calibrate, reconstruct,
export, ...). :mod:`viewer_app.panels` builds and wires the widgets against it, and
:class:`viewer_app.app.ViewerApp`, which owns the state, provides it; so the panels
never import the app. :data:`Notify` and :data:`Guard` are the two services the
smaller tools (the catheter calibration) are handed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

__all__ = ["Guard", "Notify", "PageCommands"]

#: notify(title, body, level, client): a notification on the page (level: "info",
#: "success", "warning" or "error"; client None: every connected page).
Notify = Callable[[str, str, str, object | None], None]
#: guard(what, client, func): ``func()``, a user error or a bug becoming a notification
#: about ``what`` (then None) instead of a dead page.
Guard = Callable[[str, object | None, Callable[[], object]], object]


class PageCommands(Protocol):
    """The viewer's commands, as the panels call them (each documented on ViewerApp)."""

    # ---------------------------------------------------------------- services
    def notify(self, title: str, body: str, level: str = "info",
               client: object | None = None) -> None: ...

    def guard(self, what: str, client: object | None,
              func: Callable[[], object]) -> object: ...

    # ---------------------------------------------------------------- files
    def open_pair(self, path_a: str, path_b: str, frame_a: int | None = None,
                  frame_b: int | None = None, client: object | None = None) -> bool: ...

    def open_upload(self, view: str, filename: str, content: bytes,
                    client: object | None = None) -> bool: ...

    def apply_geometry(self, entries: dict[str, dict[str, str]],
                       client: object | None = None) -> bool: ...

    def confirm_one_patient(self, client: object | None = None) -> None: ...

    def measure_catheter(self, view: str, french_text: str,
                         client: object | None = None) -> bool: ...

    # ---------------------------------------------------------------- display
    def set_frame(self, view: str, index: int) -> None: ...

    def set_window(self, view: str, level: float, width: float) -> None: ...

    def set_intensity(self, view: str, choice: str) -> None: ...

    def set_layout(self, layout: str, client: object | None = None) -> None: ...

    def zoom_at_next_click(self, factor: int) -> None: ...

    def fit_images(self) -> None: ...

    # ---------------------------------------------------------------- marks
    def set_mode(self, mode: str) -> None: ...

    def set_segment(self, name: str) -> None: ...

    def rename_segment(self, name: str, client: object | None = None) -> str | None: ...

    def new_segment(self, name: str | None = None) -> int | None: ...

    def new_branch(self, client: object | None = None) -> int | None: ...

    def select_listed(self, mark_id: int | None) -> None: ...

    def undo(self) -> bool: ...

    def delete_selected(self, client: object | None = None) -> object: ...

    def clear(self) -> None: ...

    # ---------------------------------------------------------------- seeds file
    def load_seeds(self, path: str, client: object | None = None) -> bool: ...

    def load_seeds_upload(self, content: bytes, client: object | None = None) -> bool: ...

    def save_seeds(self, path: str) -> object: ...

    # ---------------------------------------------------------------- results
    def calibrate(self, client: object | None = None) -> object: ...

    def reconstruct(self, client: object | None = None) -> object: ...

    def set_lesion(self, start_mm: float, end_mm: float,
                   reference_mm: tuple[float, float] | None = None) -> dict[str, float]: ...

    def set_ffr_colouring(self, on: bool, client: object | None = None) -> bool: ...

    def download(self, kind: str, client: object | None = None) -> None: ...
