"""Editing one mark on the page: drag it to move it, delete the selected one.

A left drag that starts on a mark's dot moves that mark: the mark follows the pointer
(drawn raw while it moves) and is snapped to the vessel where it is let go, as a click
is; the whole drag is one undo step. A drag that starts on an image elsewhere does
nothing: the image takes the gesture, so the camera never turns away from the
angiograms (viser orbits only on drags that start on empty space or on the model).

:class:`MarkEditing` is a part of :class:`viewer_app.app.ViewerApp` (its base class),
kept in its own module; it works on the app's state, declared below, and never imports
the app.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import viser

from viewer_app.scene import IMAGE_SIZE

if TYPE_CHECKING:
    from viewer_app.catheter import CatheterTool
    from viewer_app.commands import Guard
    from viewer_app.marks import Mark
    from viewer_app.scene import View
    from viewer_app.state import MarkState

__all__ = ["GRAB_RADIUS", "MarkEditing"]

#: A drag grabs the nearest mark within this distance of where it starts, in scene units
#: (an image's longer side is IMAGE_SIZE): a little more than a mark's dot.
GRAB_RADIUS = 0.016


@dataclass
class _Drag:
    """A drag in flight: the mark it moves and whether its undo step was taken."""

    view: str
    mark_id: int
    moved: bool = False


class MarkEditing:
    """Drag a mark, move one, delete the selected one."""

    # the app's state these commands use (set by ViewerApp)
    views: dict[str, View]
    state: MarkState
    catheter: CatheterTool
    _lock: threading.RLock
    # ... and the app's services (methods of ViewerApp)
    guard: Guard
    _edit_marks: Callable[..., object]
    _redraw_marks: Callable[[], None]
    _autosave: Callable[[], None]

    _drag: _Drag | None = None

    def _make_drag_callback(self, view: str) -> Callable:
        async def on_drag(event: viser.SceneNodeDragEvent) -> None:
            v = self.views[view]
            where = event.start_position if event.phase == "start" else event.end_position
            col, row = v.px_from_local(np.asarray(where, float)[:2] - v.position[:2])
            if event.phase == "start":
                self.grab_mark(view, col, row)
            else:
                self.guard("Move mark", event.client,
                           lambda: self.drag_mark_to(col, row, final=event.phase == "end"))

        return on_drag

    def grab_mark(self, view: str, col: float, row: float) -> Mark | None:
        """Start a drag at pixel (col, row) of ``view``: the mark it grabs (the nearest
        within :data:`GRAB_RADIUS`, then selected), or None (the drag moves nothing)."""
        with self._lock:
            self._drag = None
            if self.catheter.active:  # the catheter's clicks, not the marks
                return None
            v = self.views[view]
            radius_px = GRAB_RADIUS / IMAGE_SIZE * max(v.rows, v.cols)
            marks = self.state.marks_in(view)
            if not marks:
                return None
            d = np.hypot(*(np.array([m.point_px for m in marks]) - [col, row]).T)
            k = int(np.argmin(d))
            if d[k] > radius_px:
                return None
            self._drag = _Drag(view, marks[k].id)
            self.state.select(marks[k].id)
            self._redraw_marks()
            return marks[k]

    def drag_mark_to(self, col: float, row: float, final: bool = False) -> Mark | None:
        """Move the grabbed mark to pixel (col, row) of its view: raw while it moves, snapped
        to the vessel at the end (``final``: the drag ends; autosaved). Its first move is
        the undo step. None when no mark is grabbed."""
        with self._lock:
            drag = self._drag
            if drag is None:
                return None
            try:
                mark = self.state.move_mark(drag.mark_id, col, row, snap=final,
                                            undoable=not drag.moved)
                drag.moved = True
                self._redraw_marks()
                if final:
                    self._autosave()
            finally:
                if final:  # the drag ends once its mark is snapped and saved (or refused)
                    self._drag = None
            return mark

    def move_mark(self, mark_id: int, col: float, row: float,
                  client: object | None = None) -> Mark | None:
        """Move mark ``mark_id`` to pixel (col, row) of its view, snapped (one undo step);
        the mark, or None with a notification saying what is wrong."""
        return self._edit_marks("Move mark", client,
                                lambda: self.state.move_mark(mark_id, col, row))

    def delete_selected(self, client: object | None = None) -> Mark | None:
        """Delete the selected mark (one undo step); the mark deleted, or None with a
        notification saying what to select first."""
        return self._edit_marks("Delete mark", client, self.state.delete_mark)
