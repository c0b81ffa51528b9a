"""coronary3d's browser viewer (viser): the only package that imports viser.

``run_viewer`` serves the app (``coronary3d view``); ``ViewerApp`` is the app
itself, driven by tests through its public methods; ``viewer_app.state`` holds
the GUI-free state (marks, undo, seeds, epipolar lines, autosave).
"""

from viewer_app.app import DEMO_DIR, EXPORT_KINDS, ViewerApp, run_viewer

__all__ = ["DEMO_DIR", "EXPORT_KINDS", "ViewerApp", "run_viewer"]
