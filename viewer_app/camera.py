"""Each page's camera: framed on the current layout, never left tilting the angiograms.

:class:`PageCameras` frames every connected page on the layout the app shows
(:func:`viewer_app.scene.layout_framing`), frames a page again when its canvas changes
size (the docked panel, a resized window), and turns a user's rotation in an angiogram
layout into the "3D model" layout (the angiograms are hidden, the model orbits), so the
angiograms are never seen as oblique planes.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import viser

from viewer_app import scene

__all__ = ["FRAMING_SETTLE_S", "PageCameras"]

log = logging.getLogger(__name__)

FRAMING_SETTLE_S = 1.5  # camera updates this soon after the app moved the camera are its own


class PageCameras:
    """Camera handling of every page of one viser server.

    framing : returns the framing of the current layout.
    on_rotated : called with the client when a user rotated an angiogram layout.
    """

    def __init__(self, server: viser.ViserServer, framing: Callable[[], scene.Framing],
                 on_rotated: Callable[[viser.ClientHandle], None]) -> None:
        self.server = server
        self.framing = framing
        self.on_rotated = on_rotated
        self.rotation_matters = True  # False in the "3D model" layout
        self._framing_now = False
        self._framed_aspect: dict[int, float] = {}  # client id -> canvas aspect when framed
        self._framed_at: dict[int, float] = {}  # client id -> time.monotonic() when framed
        server.initial_camera.up = (0.0, -1.0, 0.0)
        server.on_client_connect(self._on_connect)

    def _on_connect(self, client: viser.ClientHandle) -> None:
        def on_camera(_camera: object) -> None:
            if self._framing_now:
                return
            framed = self._framed_aspect.get(client.client_id)
            if framed is not None and abs(float(client.camera.aspect) - framed) > 0.02:
                self.frame(client)  # the canvas changed size (panel docked, resize)
                return
            if time.monotonic() - self._framed_at.get(client.client_id, 0.0) < FRAMING_SETTLE_S:
                return  # our own camera move (the page animates it) is not the user's
            if self.rotation_matters and scene.camera_rotated_deg(client) > scene.ROTATED_DEG:
                self.on_rotated(client)

        client.camera.on_update(on_camera)
        self.frame(client)

    def frame(self, client: viser.ClientHandle) -> None:
        """Set one page's camera to the current framing."""
        self._framing_now = True
        try:
            self._framed_aspect[client.client_id] = float(client.camera.aspect)
            self._framed_at[client.client_id] = time.monotonic()
            scene.apply_framing(client, self.framing())
        except Exception:  # a client that went away
            log.debug("camera framing failed", exc_info=True)
        finally:
            self._framing_now = False

    def frame_all(self) -> None:
        """The initial camera of pages still to (re)load, and every connected page."""
        fr = self.framing()
        dist = scene.camera_distance(fr, aspect=1.1)  # canvas beside the docked panel
        cam = self.server.initial_camera
        cam.look_at = tuple(fr.centre)
        cam.position = tuple(fr.centre - scene.STRAIGHT * dist)
        for c in list(self.server.get_clients().values()):
            self.frame(c)
