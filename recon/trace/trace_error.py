"""The tracing stage's error: one line naming the view, the clicks and what to do."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from recon.errors import CoronaryError

__all__ = ["TraceError"]


class TraceError(CoronaryError):
    """A click or segment that cannot be traced; the one-line message names the view and click.

    Attributes
    ----------
    view : the view's name ("A", "B") or None.
    near_px : (2,) (col, row) of the place to look at (where a waypoint would
        help), or None.
    """

    def __init__(
        self, message: str, *, view: str | None = None, near_px: ArrayLike | None = None
    ) -> None:
        super().__init__(" ".join(str(message).split()))
        self.view = view
        self.near_px = None if near_px is None else np.asarray(near_px, dtype=float).reshape(2)

    def __reduce__(self):  # keeps the attributes through pickling (worker processes)
        return (_rebuild, (str(self), self.view, self.near_px))


def _rebuild(message: str, view: str | None, near_px: ArrayLike | None) -> TraceError:
    return TraceError(message, view=view, near_px=near_px)
