"""A mark: one click placed on an angiogram, and the click modes that place them.

Below :mod:`viewer_app.state` (which keeps the marks of a pair) and the modules that
draw or describe marks. Pixel coordinates are (col, row), 0-based.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "KIND_WORDS",
    "MAX_GROUPS",
    "MODES",
    "MODE_LABELS",
    "ONE_SHOT_MODES",
    "VIEWS",
    "Mark",
    "check_view",
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

