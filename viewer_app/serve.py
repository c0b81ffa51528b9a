"""Serving the viewer from the command line: start, wait, stop."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path

from recon.io.isolated import start_fork_server
from recon.io.overrides import GeometryOverrides, header_replacements
from viewer_app.app import ViewerApp

__all__ = ["run_viewer"]

log = logging.getLogger("viewer_app.app")  # the app's logger: one place for its records


def run_viewer(
    path_a: str | None,
    path_b: str | None,
    seeds_path: str | None,
    host: str = "127.0.0.1",
    port: int = 8080,
    frame_a: int | None = None,
    frame_b: int | None = None,
    on_ready: Callable[[str], None] | None = None,
    autosave_path: str | Path | None = None,
    stop_event: threading.Event | None = None,
    overrides_a: GeometryOverrides | None = None,
    overrides_b: GeometryOverrides | None = None,
    out_dir: str | Path | None = None,
) -> None:
    """Serve the viewer until interrupted (Ctrl-C) or ``stop_event`` is set.

    ``on_ready(url)`` is called once the server listens (the CLI prints the
    URL). Both paths None opens the bundled demo case. Raises LoadError /
    SeedsError (one line) when the initial files cannot be used.
    """
    app = ViewerApp(path_a, path_b, seeds_path, host=host, port=port, frame_a=frame_a,
                    frame_b=frame_b, autosave_path=autosave_path, overrides_a=overrides_a,
                    overrides_b=overrides_b, out_dir=out_dir)
    for v in app.views.values():  # a header value replaced by a flag is said, not silent
        for note in header_replacements(v.angio.geometry_notes):
            log.warning("%s: %s", v.display_name, note)
            app.notify("Header value replaced", f"{v.key.upper()}: {note}", "warning")
    # Reconstruct runs in a child forked from a server that has the pipeline imported
    threading.Thread(target=start_fork_server, daemon=True).start()
    if on_ready is not None:
        on_ready(app.url)
    stop = stop_event or threading.Event()
    try:
        while not stop.wait(0.5):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        app.stop()
