"""A long command's note in the page: one loading notification per client, removed after."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator

__all__ = ["loading_notes"]

log = logging.getLogger(__name__)


@contextlib.contextmanager
def loading_notes(clients: list, title: str) -> Iterator[list]:
    """A loading notification titled ``title`` in each of ``clients`` (viser client
    handles) while the block runs; yields the notifications' handles (set their ``body``
    to show progress). A client that went away is skipped."""
    handles = []
    for c in clients:
        try:
            handles.append(c.add_notification(title, "starting", loading=True,
                                              with_close_button=False))
        except Exception:
            log.debug("notification failed", exc_info=True)
    try:
        yield handles
    finally:
        for h in handles:
            try:
                h.remove()
            except Exception:
                log.debug("notification removal failed", exc_info=True)
