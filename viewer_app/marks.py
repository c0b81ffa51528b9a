"""A mark: one click placed on an angiogram, the click modes that place them, and the
visible part of a mark's epipolar line.

Below :mod:`viewer_app.state` (which keeps the marks of a pair) and the modules that
draw or describe marks. Pixel coordinates are (col, row), 0-based.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "KIND_WORDS",
    "MAX_GROUPS",
    "MODES",
    "MODE_LABELS",
    "ONE_SHOT_MODES",
    "VIEWS",
    "Mark",
    "check_view",
    "clip_line_to_image",
    "mark_from_entry",
    "other_view",
]

MODES: tuple[str, ...] = ("guided", "proximal", "waypoint", "distal", "feature")
ONE_SHOT_MODES = ("proximal", "distal")  # redo one end, then back to guided
MODE_LABELS: dict[str, str] = {
    "guided": "Guided (ends, then landmarks)",
    "proximal": "Segment proximal end",
    "waypoint": "Waypoint",
    "distal": "Segment distal end",
    "feature": "Landmark pair (A and B)",
}
KIND_WORDS = {"proximal": "proximal end", "distal": "distal end", "feature": "landmark",
              "waypoint": "waypoint"}
VIEWS: tuple[str, str] = ("a", "b")
MAX_GROUPS = 1000  # segments or features of one pair (seeds files hold at most 100 / 1000)

FloatArray = NDArray[np.float64]


def other_view(view: str) -> str:
    return "b" if view == "a" else "a"


def check_view(view: str) -> str:
    if view not in VIEWS:
        raise ValueError(f"view must be 'a' or 'b', got {view!r}")
    return view


@dataclass(frozen=True)
class Mark:
    """One placed click.

    Attributes
    ----------
    id : unique, increasing in click order.
    kind : one of :data:`MODES`.
    view : "a" or "b".
    group : segment index (proximal/waypoint/distal) or feature index.
    point_px : (2,) placed position (col, row), snapped when possible.
    raw_px : (2,) where the user clicked.
    snap_distance_px : distance from raw to snapped point, None if kept raw.
    """

    id: int
    kind: str
    view: str
    group: int
    point_px: tuple[float, float]
    raw_px: tuple[float, float]
    snap_distance_px: float | None = None

    def to_dict(self) -> dict:
        return {
            "id": self.id,
            "kind": self.kind,
            "view": self.view,
            "group": self.group,
            "point_px": list(self.point_px),
            "raw_px": list(self.raw_px),
            "snap_distance_px": self.snap_distance_px,
        }

    @classmethod
    def from_dict(cls, data: dict) -> Mark:
        return cls(
            id=int(data["id"]),
            kind=str(data["kind"]),
            view=str(data["view"]),
            group=int(data["group"]),
            point_px=(float(data["point_px"][0]), float(data["point_px"][1])),
            raw_px=(float(data["raw_px"][0]), float(data["raw_px"][1])),
            snap_distance_px=(
                None if data.get("snap_distance_px") is None else float(data["snap_distance_px"])
            ),
        )


def mark_from_entry(entry: object) -> Mark | None:
    """A mark from its autosave entry, or None when the entry is damaged."""
    if not isinstance(entry, dict):
        return None
    try:
        mark = Mark.from_dict(entry)
    except (KeyError, TypeError, ValueError, IndexError, OverflowError):
        return None
    coords = (*mark.point_px, *mark.raw_px)
    if (mark.kind not in MODES or mark.view not in VIEWS or not 0 <= mark.group < MAX_GROUPS
            or mark.id < 1 or not all(np.isfinite(coords))):
        return None
    return mark


def clip_line_to_image(line: ArrayLike, cols: int, rows: int) -> FloatArray | None:
    """Clip a line a col + b row + c = 0 to the image rectangle.

    Parameters
    ----------
    line : (3,) line coefficients (a, b, c).
    cols, rows : image size; the rectangle spans [-0.5, cols - 0.5] x [-0.5, rows - 0.5].

    Returns
    -------
    (2, 2) end points (col, row) of the visible part, or None if the line
    misses the image.
    """
    a, b, c = (float(x) for x in np.asarray(line, dtype=float).reshape(3))
    lo_c, hi_c, lo_r, hi_r = -0.5, cols - 0.5, -0.5, rows - 0.5
    cand: list[tuple[float, float]] = []
    if abs(b) > 1e-12:  # intersections with the left and right borders
        for col in (lo_c, hi_c):
            cand.append((col, -(a * col + c) / b))
    if abs(a) > 1e-12:  # intersections with the top and bottom borders
        for row in (lo_r, hi_r):
            cand.append((-(b * row + c) / a, row))
    eps = 1e-9
    pts = np.array(
        [p for p in cand if lo_c - eps <= p[0] <= hi_c + eps and lo_r - eps <= p[1] <= hi_r + eps]
    ).reshape(-1, 2)
    if len(pts) < 2:
        return None
    direction = np.array([-b, a])  # along the line
    t = pts @ direction
    seg = np.stack([pts[np.argmin(t)], pts[np.argmax(t)]])
    if np.linalg.norm(seg[1] - seg[0]) < 1e-9:
        return None
    return seg
