"""The viewer's state without any GUI: marks, modes, undo, seeds, epipolar lines.

Nothing here imports viser; :mod:`viewer_app.app` wires this state to the
browser and autosaves it (:mod:`viewer_app.autosave` writes :meth:`MarkState.to_dict`).
Pixel coordinates follow the project's C-arm convention: (col, row), 0-based, (0, 0)
the centre of the top-left pixel.

A clinician places marks in a *mode*:

- ``"guided"`` (the default): a click in a view places the first thing that
  view still lacks: the proximal end of the current segment, then its distal
  end, then landmarks (a landmark clicked in one view waits for its partner
  in the other). Any order of views works; the epipolar line drawn after a
  click is the one the next click in the other view should land on;
- ``"proximal"`` / ``"distal"``: redo that end (one click, then back to
  guided);
- ``"proximal"`` / ``"distal"``: the ends of the current segment in the
  clicked view (one of each per view and segment; a new click replaces it);
- ``"waypoint"``: a point between the ends that keeps the trace on the
  vessel (any number per view, kept in click order);
- ``"feature"``: a landmark seen in both views, clicked in one view and then
  its partner in the other.

The marks convert to and from :class:`recon.seeds.Seeds` (the same
seeds.json the command line reads).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from recon.geometry import ViewGeometry, epipolar_lines
from recon.seeds import MAX_NAME_CHARS, Feature, Seeds, Segment, seeds_from_dict
from viewer_app.guide import GuidedOrder
from viewer_app.marks import (
    MODE_LABELS,
    MODES,
    ONE_SHOT_MODES,
    VIEWS,
    Mark,
    check_view,
    clip_line_to_image,
    mark_from_entry,
    other_view,
)
from viewer_app.saved_names import read_names

__all__ = [
    "MODES",
    "MODE_LABELS",
    "Mark",
    "MarkState",
    "clip_line_to_image",
]

FloatArray = NDArray[np.float64]

#: A landmark clicked this close (px) to one already placed in that view is the same
#: landmark placed again (not a second pair at the same place).
SAME_LANDMARK_PX = 4.0

# A snapper takes (view, raw click (2,)) and returns (placed point (2,), snap distance in
# px or None when the click was kept raw, a one-line message for the user or None).
Snapper = Callable[[str, FloatArray], tuple[FloatArray, float | None, str | None]]


class MarkState(GuidedOrder):
    """Marks of one image pair, with undo, modes, selection and epipolar lines (the guided
    order and the guide line: :class:`viewer_app.guide.GuidedOrder`).

    Parameters
    ----------
    view_a, view_b : nominal geometries of the two views (view B may later be
        replaced by its calibrated geometry with :meth:`set_calibrated_b`).
    snapper : optional function snapping a click to the vessel (see ``Snapper``).
    header_check_px : before Calibrate, a correspondence this far (px) from its magenta
        line asks for a landmark pair first (viewer_app.guide); None: never.
    """

    def __init__(
        self,
        view_a: ViewGeometry,
        view_b: ViewGeometry,
        snapper: Snapper | None = None,
        header_check_px: float | None = None,
    ) -> None:
        self.header_check_px = header_check_px
        self.view_a = view_a
        self.view_b_nominal = view_b
        self.view_b_calibrated: ViewGeometry | None = None
        self.snapper = snapper
        self.mode: str = "guided"
        self.marks: list[Mark] = []
        self.segment_names: list[str] = ["Segment 1"]
        self.feature_names: dict[int, str] = {}  # feature group -> name (from a seeds file)
        # branch name -> (parent segment, bifurcation feature), seeds format v2
        self.segment_links: dict[str, tuple[str, str]] = {}
        self.current_segment: int = 0
        self.selected_id: int | None = None
        self._next_id: int = 1
        self._history: list[tuple] = []
        self.last_message: str | None = None
        self.last_epipolar_ms: float = 0.0
        self._guide_id: int | None = None  # mark whose epipolar line guides the next click

    # ------------------------------------------------------------ geometry
    @property
    def view_b(self) -> ViewGeometry:
        """View B's geometry in use: calibrated if available, else nominal."""
        return self.view_b_calibrated if self.view_b_calibrated is not None else self.view_b_nominal

    def geometry(self, view: str) -> ViewGeometry:
        return self.view_a if check_view(view) == "a" else self.view_b

    def set_calibrated_b(self, view_b: ViewGeometry | None) -> None:
        """Use a calibrated geometry for view B (None: back to the header geometry)."""
        self.view_b_calibrated = view_b

    # ------------------------------------------------------------ undo
    def _snapshot(self) -> tuple:
        return (
            list(self.marks),
            list(self.segment_names),
            self.current_segment,
            self.selected_id,
            self._next_id,
            dict(self.segment_links),
        )

    def _push(self) -> None:
        self._history.append(self._snapshot())
        del self._history[:-200]

    def undo(self) -> bool:
        """Revert the last change of the marks. Returns False if there was nothing to undo."""
        if not self._history:
            return False
        self._guide_id = None
        self.last_message = None  # it was about a click this undoes, or an earlier one
        (
            self.marks,
            self.segment_names,
            self.current_segment,
            self.selected_id,
            self._next_id,
            self.segment_links,
        ) = self._history.pop()
        return True

    def clear(self) -> None:
        """Remove all marks (undoable)."""
        self._push()
        self.last_message = None
        self.marks = []
        self.segment_names = ["Segment 1"]
        self.segment_links = {}
        self.current_segment = 0
        self.selected_id = None

    # ------------------------------------------------------------ modes
    def set_mode(self, mode: str) -> None:
        if mode not in MODES:
            raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
        self.mode = mode

    def new_segment(self, name: str | None = None) -> int:
        """Start a new segment and make it current; returns its index."""
        self._push()
        self.segment_names.append(name or self._free_name())
        self.current_segment = len(self.segment_names) - 1
        return self.current_segment

    def _free_name(self) -> str:
        """"Segment N" for the next segment (N its number), or the first such name no
        segment has (a tree's names must differ)."""
        n = len(self.segment_names) + 1
        while f"Segment {n}" in self.segment_names:
            n += 1
        return f"Segment {n}"

    def new_branch(self, name: str | None = None) -> int:
        """Start a branch of the current segment at the selected landmark; returns its index.

        The selected mark must be a landmark placed in both views: the bifurcation. The
        new segment becomes current, its link (parent: the current segment; bifurcation:
        that landmark's name) goes to :attr:`segment_links`, and its proximal end is
        placed on the landmark in both views (a branch starts at its bifurcation; the
        "proximal" mode redoes it). One undo step. Raises ValueError saying what to
        click first when no such landmark is selected.
        """
        mark = self.selected
        if mark is None or mark.kind != "feature":
            raise ValueError("New branch: first select the bifurcation landmark: click it in "
                             "A and in B (mode 'Landmark pair (A and B)'), or pick it under "
                             "'Selected mark'; the branch leaves the current segment there")
        partner = self.partner(mark)
        if partner is None:
            raise ValueError(f"New branch: landmark {self.label(mark)} is only in "
                             f"{mark.view.upper()}; click the bifurcation in "
                             f"{other_view(mark.view).upper()} too (on the magenta line)")
        if name is not None and name in self.segment_names:
            raise ValueError(f"New branch: a segment is already called {name!r}")
        parent = self.segment_names[self.current_segment]
        self._push()
        name = name or self._free_name()
        self.segment_names.append(name)
        index = len(self.segment_names) - 1
        self.segment_links[name] = (parent, self.feature_name(mark.group))
        for m in (mark, partner):
            self.marks.append(Mark(self._next_id, "proximal", m.view, index, m.point_px,
                                   m.point_px, None))
            self._next_id += 1
        self.current_segment = index
        self.selected_id = None
        self._guide_id = None
        return index

    def feature_name(self, group: int) -> str:
        """The name landmark ``group`` has in the seeds (a seeds file's, else "feature N")."""
        return self.feature_names.get(group) or f"feature {group + 1}"

    def parent_of(self, name: str) -> tuple[str, str] | None:
        """(parent segment, bifurcation landmark) of the segment called ``name`` when it is
        a branch, else None."""
        return self.segment_links.get(name)

    def rename_segment(self, name: str) -> str:
        """Rename the current segment (one undo step); the links of its branches, and its
        own, follow. Returns the name as kept (spaces collapsed). Raises ValueError
        saying what is wrong with an empty or over-long name, or one another segment has.
        """
        new = " ".join("".join(ch if ch.isprintable() else " " for ch in str(name)).split())
        old = self.segment_names[self.current_segment]
        if not new or len(new) > MAX_NAME_CHARS:
            raise ValueError(f"Rename: type a name of 1 to {MAX_NAME_CHARS} characters for "
                             f"{old!r} in the Segment name field first")
        if new != old and new in self.segment_names:
            raise ValueError(f"Rename: another segment is already called {new!r}")
        if new != old:
            self._push()
            self.segment_names[self.current_segment] = new
            self.segment_links = {(new if k == old else k): (new if p == old else p, f)
                                  for k, (p, f) in self.segment_links.items()}
        return new

    def set_current_segment(self, index: int) -> None:
        if not 0 <= index < len(self.segment_names):
            raise ValueError(f"no segment {index} (there are {len(self.segment_names)})")
        self.current_segment = index

    # ------------------------------------------------------------ marks
    def _place(self, view: str, raw_px: FloatArray) -> tuple[FloatArray, float | None]:
        self.last_message = None
        if self.snapper is None:
            return raw_px, None
        point, distance, message = self.snapper(view, raw_px)
        self.last_message = message
        return np.asarray(point, dtype=float).reshape(2), distance

    def click(self, view: str, col: float, row: float) -> Mark:
        """Place a mark at pixel (col, row) of ``view`` in the current mode.

        The click is snapped to the vessel by the snapper if there is one; a
        click too far from any vessel is kept raw and :attr:`last_message`
        says so. Returns the new mark, which becomes the selected one.
        """
        check_view(view)
        geom = self.geometry(view)
        if not (-0.5 <= col <= geom.cols - 0.5 and -0.5 <= row <= geom.rows - 0.5):
            raise ValueError(
                f"click ({col:.1f}, {row:.1f}) is outside image {view.upper()} "
                f"({geom.cols}x{geom.rows})"
            )
        raw = np.array([col, row], dtype=float)
        point, distance = self._place(view, raw)
        self._push()
        kind = self.mode if self.mode != "guided" else self.guided_kind(view)
        if kind == "feature":
            group = self._feature_group_for(view, point)
        else:
            group = self.current_segment
        if kind in ("proximal", "distal", "feature"):  # one per (kind, view, group)
            self.marks = [
                m
                for m in self.marks
                if not (m.kind == kind and m.view == view and m.group == group)
            ]
        mark = Mark(
            id=self._next_id,
            kind=kind,
            view=view,
            group=group,
            point_px=(float(point[0]), float(point[1])),
            raw_px=(float(raw[0]), float(raw[1])),
            snap_distance_px=distance,
        )
        self._next_id += 1
        self.marks.append(mark)
        self.selected_id = mark.id
        if self.mode in ONE_SHOT_MODES:
            self.mode = "guided"
        self._guide_id = self._guide_after(mark) if self.mode == "guided" else None
        return mark

    def _feature_group_for(self, view: str, point_px: FloatArray | None = None) -> int:
        """Feature index a click in ``view`` (at ``point_px``, when known) goes to: the
        landmark already placed in ``view`` within :data:`SAME_LANDMARK_PX` of the click
        (it is placed again, not counted twice), else the oldest landmark of the other
        view still waiting for its partner (landmarks pair in the order they were
        clicked: all of A's, then all of B's, pair one by one), else a new one."""
        if point_px is not None:
            for m in self.marks:
                if (m.kind == "feature" and m.view == view and float(np.hypot(
                        *(np.asarray(m.point_px) - point_px))) <= SAME_LANDMARK_PX):
                    return m.group
        groups: dict[int, set[str]] = {}
        for m in self.marks:
            if m.kind == "feature":
                groups.setdefault(m.group, set()).add(m.view)
        for g in sorted(groups):
            if groups[g] == {other_view(view)}:
                return g
        return max(groups) + 1 if groups else 0

    def marks_by_group(self, group: int, view: str, kind: str = "feature") -> Mark:
        """The mark of ``kind`` (a landmark by default) of ``group`` in ``view``."""
        return next(m for m in self.marks if m.kind == kind and m.group == group
                    and m.view == view)

    # ------------------------------------------------------------ editing one mark
    def move_mark(self, mark_id: int, col: float, row: float, snap: bool = True,
                  undoable: bool = True) -> Mark:
        """Put mark ``mark_id`` at pixel (col, row) of its view (snapped to the vessel as
        a click is, with ``snap``); it keeps its kind, group and id and becomes the
        selected mark. One undo step with ``undoable`` (a drag's intermediate positions
        are not: its first move is). Raises ValueError for no such mark or a place
        outside the image."""
        mark = self.mark_by_id(mark_id)
        if mark is None:
            raise ValueError(f"no mark with id {mark_id}")
        geom = self.geometry(mark.view)
        col = float(np.clip(col, -0.5, geom.cols - 0.5))
        row = float(np.clip(row, -0.5, geom.rows - 0.5))
        raw = np.array([col, row], dtype=float)
        point, distance = self._place(mark.view, raw) if snap else (raw, None)
        if undoable:
            self._push()
        moved = replace(mark, point_px=(float(point[0]), float(point[1])),
                        raw_px=(col, row), snap_distance_px=distance)
        self.marks = [moved if m.id == mark_id else m for m in self.marks]
        self.selected_id, self._guide_id = mark_id, None
        return moved

    def delete_mark(self, mark_id: int | None = None) -> Mark:
        """Remove one mark (default: the selected one); one undo step. A landmark's
        partner then waits for a new partner. Raises ValueError when there is no such
        mark (or nothing is selected)."""
        mark = self.mark_by_id(self.selected_id if mark_id is None else mark_id)
        if mark is None:
            raise ValueError("Delete: select a mark first (click it, drag it, or pick it "
                             "under 'Selected mark')")
        self._push()
        self.last_message = None
        self.marks = [m for m in self.marks if m.id != mark.id]
        self.selected_id, self._guide_id = None, None
        return mark

    def select(self, mark_id: int | None) -> None:
        if mark_id is not None and self.mark_by_id(mark_id) is None:
            raise ValueError(f"no mark with id {mark_id}")
        self.selected_id = mark_id
        self._guide_id = None

    def mark_by_id(self, mark_id: int | None) -> Mark | None:
        for m in self.marks:
            if m.id == mark_id:
                return m
        return None

    @property
    def selected(self) -> Mark | None:
        return self.mark_by_id(self.selected_id)

    def marks_in(self, view: str) -> list[Mark]:
        return [m for m in self.marks if m.view == view]

    def label(self, mark: Mark) -> str:
        """Short label drawn next to a mark: 1p, 1d, 1w2 (segment 1: proximal end, distal
        end, waypoint 2), F3 (landmark 3). The segment's number comes first, in lower case,
        so that a label never reads as a vessel's name (D1, OM1, S1)."""
        if mark.kind == "feature":
            return f"F{mark.group + 1}"
        if mark.kind == "waypoint":
            same = [
                m.id
                for m in self.marks
                if m.kind == "waypoint" and m.view == mark.view and m.group == mark.group
            ]
            return f"{mark.group + 1}w{same.index(mark.id) + 1}"
        return f"{mark.group + 1}{'p' if mark.kind == 'proximal' else 'd'}"

    def partner(self, mark: Mark) -> Mark | None:
        """The corresponding mark in the other view (segment end or feature), if placed."""
        if mark.kind == "waypoint":
            return None
        for m in self.marks:
            if m.kind == mark.kind and m.group == mark.group and m.view != mark.view:
                return m
        return None

    # ------------------------------------------------------------ epipolar
    def epipolar_segment(self, mark: Mark | None = None) -> tuple[str, FloatArray] | None:
        """Epipolar line of a mark (default: the one guiding the next click after a guided
        click, else the selected one), drawn in the other view.

        Returns (view the line is drawn in, (2, 2) end points (col, row) clipped
        to that image), or None when nothing is selected or the line misses the
        image. Uses the calibrated view B when there is one (eq. 4 through
        :func:`recon.geometry.epipolar_lines`).
        """
        t0 = time.perf_counter()
        if mark is None:
            mark = self.mark_by_id(self._guide_id) or self.selected
        if mark is None:
            return None
        src, dst = self.geometry(mark.view), self.geometry(other_view(mark.view))
        line = epipolar_lines(np.asarray([mark.point_px]), src, dst)[0]
        seg = clip_line_to_image(line, dst.cols, dst.rows)
        self.last_epipolar_ms = (time.perf_counter() - t0) * 1e3
        return None if seg is None else (other_view(mark.view), seg)

    # ------------------------------------------------------------ seeds
    def to_seeds(self) -> Seeds:
        """The complete marks as seeds: segments with both ends in both views, paired features.

        A branch (:attr:`segment_links`) keeps its parent and bifurcation when both are
        complete (the parent earlier); otherwise it is written as a root for now."""
        features = self._complete_features()
        feature_names = {f.name for f in features}
        segments: list[Segment] = []
        for g, name in enumerate(self.segment_names):
            views: dict[str, list[tuple[float, float]]] = {}
            for view in VIEWS:
                ends = {
                    m.kind: m.point_px
                    for m in self.marks
                    if m.view == view and m.group == g and m.kind in ("proximal", "distal")
                }
                if len(ends) < 2:
                    break
                way = [
                    m.point_px
                    for m in self.marks
                    if m.view == view and m.group == g and m.kind == "waypoint"
                ]
                views[view] = [ends["proximal"], *way, ends["distal"]]
            if len(views) == 2:
                parent, bifurcation = self.segment_links.get(name, (None, None))
                if parent not in {s.name for s in segments} or bifurcation not in feature_names:
                    parent = bifurcation = None
                segments.append(Segment(name=name, a_px=tuple(views["a"]), b_px=tuple(views["b"]),
                                        parent=parent, bifurcation=bifurcation))
        return Seeds(segments=tuple(segments), features=features)

    def _complete_features(self) -> tuple[Feature, ...]:
        """Features with a mark in both views, by group, with their names."""
        features = []
        groups = sorted({m.group for m in self.marks if m.kind == "feature"})
        for g in groups:
            pts = {m.view: m.point_px for m in self.marks if m.kind == "feature" and m.group == g}
            if len(pts) == 2:
                features.append(Feature(name=self.feature_name(g), a_px=pts["a"],
                                        b_px=pts["b"]))
        return tuple(features)

    def missing(self) -> list[str]:
        """One line per incomplete item, e.g. 'Segment 1: distal end missing in B'."""
        out = []
        for g, name in enumerate(self.segment_names):
            for view in VIEWS:
                kinds = {m.kind for m in self.marks if m.view == view and m.group == g}
                for end in ("proximal", "distal"):
                    if end not in kinds:
                        out.append(f"{name}: {end} end missing in {view.upper()}")
        for g in sorted({m.group for m in self.marks if m.kind == "feature"}):
            views = {m.view for m in self.marks if m.kind == "feature" and m.group == g}
            for view in VIEWS:
                if view not in views:
                    out.append(f"feature {g + 1}: partner missing in {view.upper()}")
        return out

    def load_seeds(self, seeds: Seeds) -> None:
        """Replace the marks by those of ``seeds`` (undoable); points are not re-snapped."""
        self._push()
        self.last_message = None
        marks: list[Mark] = []
        next_id = 1

        def add(kind: str, view: str, group: int, p: tuple[float, float]) -> None:
            nonlocal next_id
            pt = (float(p[0]), float(p[1]))
            marks.append(Mark(next_id, kind, view, group, pt, pt, None))
            next_id += 1

        for g, seg in enumerate(seeds.segments):
            for view, pts in (("a", seg.a_px), ("b", seg.b_px)):
                add("proximal", view, g, pts[0])
                for p in pts[1:-1]:
                    add("waypoint", view, g, p)
                add("distal", view, g, pts[-1])
        for g, feat in enumerate(seeds.features):
            add("feature", "a", g, feat.a_px)
            add("feature", "b", g, feat.b_px)
        self.marks = marks
        self.segment_names = [s.name for s in seeds.segments] or ["Segment 1"]
        self.feature_names = {g: f.name for g, f in enumerate(seeds.features) if f.name}
        self.segment_links = {s.name: (s.parent, s.bifurcation) for s in seeds.segments
                              if s.parent is not None and s.bifurcation is not None}
        self.current_segment = 0
        self.selected_id = None
        self._next_id = next_id

    # ------------------------------------------------------------ autosave form
    def to_dict(self) -> dict:
        """Seeds document plus the full viewer state (incomplete marks, raw clicks, names)."""
        doc = self.to_seeds().to_dict()
        doc["viewer"] = {
            "marks": [m.to_dict() for m in self.marks],
            "segment_names": list(self.segment_names),
            "feature_names": {str(g): n for g, n in sorted(self.feature_names.items())},
            "current_segment": self.current_segment,
            "mode": self.mode,
            "segment_links": {k: list(v) for k, v in sorted(self.segment_links.items())},
        }
        return doc

    def restore_dict(self, doc: dict, source: str = "autosave") -> int:
        """Inverse of :meth:`to_dict`; a plain seeds document is accepted too.

        Marks that cannot be read (a damaged entry) are skipped, the others
        restored; returns how many were skipped. Raises ValueError when nothing
        of the viewer state can be read.
        """
        viewer = doc.get("viewer") if isinstance(doc, dict) else None
        if not isinstance(viewer, dict):
            self.load_seeds(seeds_from_dict(doc, source=source))
            return 0
        entries = viewer.get("marks")
        if not isinstance(entries, list):
            raise ValueError(f"{source}: damaged viewer state (no list of marks)")
        marks: list[Mark] = []
        for entry in entries:
            mark = mark_from_entry(entry)
            if mark is None or any(m.id == mark.id for m in marks):
                continue
            marks.append(mark)
        needed = max((m.group + 1 for m in marks if m.kind != "feature"), default=1)
        names, feature_names, links = read_names(doc, viewer, needed)
        self._push()
        self.marks = marks
        self.segment_names = names or ["Segment 1"]
        self.feature_names = feature_names
        self.segment_links = links
        current = viewer.get("current_segment", 0)
        current = current if isinstance(current, int) and not isinstance(current, bool) else 0
        self.current_segment = min(max(current, 0), len(self.segment_names) - 1)
        if viewer.get("mode") in MODES:
            self.mode = viewer["mode"]
        self.selected_id = None
        self._next_id = max((m.id for m in marks), default=0) + 1
        return len(entries) - len(marks)
