"""coronary3d's browser viewer (viser): the only package that imports viser.

``run_viewer`` serves the app (``coronary3d view``); ``ViewerApp`` is the app
itself, driven by tests through its public methods. Inside: ``app`` (the
server and its commands), ``scene`` (the 3D scene), ``tree_view`` (a vessel
tree's reconstruction and drawing), ``panels`` (the GUI, wired against
``commands.PageCommands``, which the app provides: nothing imports the app back),
``results`` and ``plot`` (the panels' texts and chart, pure), ``state`` (the
GUI-free state: marks, undo, seeds, epipolar lines) and ``autosave``.
"""

from viewer_app.app import EXPORT_KINDS, ViewerApp
from viewer_app.serve import run_viewer

__all__ = ["EXPORT_KINDS", "ViewerApp", "run_viewer"]
