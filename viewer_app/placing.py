"""Where labels go on an angiogram so that they do not print over one another: a mark's
label beside its dot, a branch's name or the MLD's beside its place, clear of the marks
and their labels. Sizes are in scene units (an image's longer side is 1; y grows down).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DOT_RADIUS",
    "LABEL_HEIGHT",
    "LABEL_PLACES",
    "MLD_PLACES",
    "MARK_LABEL_WIDTH",
    "NAME_CHAR",
    "NAME_PLACES",
    "clear_place",
    "end_places",
    "hits",
    "label_box",
    "label_places",
    "name_place",
]

FloatArray = NDArray[np.float64]

#: Where a mark's label goes (offset from the mark in scene units, anchor): below right;
#: for a second mark on the same spot above right, for a third on the left.
LABEL_PLACES = ((np.array([0.008, 0.008, 0.0]), "top-left"),
                (np.array([0.008, -0.008, 0.0]), "bottom-left"),
                (np.array([-0.008, 0.0, 0.0]), "center-right"))


#: A label's size on the page in scene units (an image is 1 wide): a mark's label (a few
#: characters) and the height of every label, as measured on the browser tests'
#: screenshots.
MARK_LABEL_WIDTH, LABEL_HEIGHT = 0.045, 0.03


def label_box(at: FloatArray, anchor: str, width: float,
              height: float = LABEL_HEIGHT) -> FloatArray:
    """The box (x0, x1, y0, y1) of a label ``width`` x ``height`` placed at ``at`` (2,) by
    its ``anchor`` (viser's "top-left", ..., "center-right"; y grows downwards)."""
    vertical, horizontal = anchor.split("-")
    x0 = at[0] - {"left": 0.0, "center": width / 2, "right": width}[horizontal]
    y0 = at[1] - {"top": 0.0, "center": height / 2, "bottom": height}[vertical]
    return np.array([x0, x0 + width, y0, y0 + height])


def label_places(pts: FloatArray) -> list[tuple[FloatArray, str]]:
    """Where the label of each mark at ``pts`` (M, 3) goes (:data:`LABEL_PLACES`), in
    order: the first place whose label clears the labels placed before it (two waypoints
    a few pixels apart, a branch's start on its bifurcation landmark), else the one that
    overlaps them least."""
    placed: list[FloatArray] = []
    out = []
    for p in np.asarray(pts, dtype=float).reshape(-1, 3):
        boxes, overlaps = [], []
        for offset, anchor in LABEL_PLACES:
            box = label_box(p[:2] + offset[:2], anchor, MARK_LABEL_WIDTH)
            boxes.append(box)
            overlaps.append(sum(max(0.0, min(box[1], b[1]) - max(box[0], b[0]))
                                * max(0.0, min(box[3], b[3]) - max(box[2], b[2]))
                                for b in placed))
            if overlaps[-1] == 0.0:
                break
        k = int(np.argmin(overlaps))
        placed.append(boxes[k])
        out.append(LABEL_PLACES[k])
    return out


#: Where a branch's name may go beside its distal end on an image (offset in scene units,
#: anchor), above right first (the end mark's own label is below right).
NAME_PLACES = ((np.array([0.01, -0.01]), "bottom-left"), (np.array([-0.01, -0.01]), "bottom-right"),
               (np.array([-0.01, 0.01]), "top-right"), (np.array([0.01, 0.01]), "top-left"))
#: Per character of a branch's name on the page, in scene units (an image is 1 wide), and
#: a mark's dot's radius, as measured on the browser tests' screenshots.
NAME_CHAR, DOT_RADIUS = 0.012, 0.008


def name_place(end_xy: NDArray[np.float64], name: str, marks_xyz: NDArray,
               places: tuple = NAME_PLACES) -> tuple[NDArray[np.float64], str]:
    """Where a name goes beside the point ``end_xy`` (2,) (a branch's distal end, the MLD)
    on an image whose marks are at ``marks_xyz`` (M, 3) (scene units, the image's frame):
    the first of ``places`` ((offset (2,), anchor), default :data:`NAME_PLACES`) whose
    text clears every mark's dot and label (placed as scene.draw_marks places them), else
    the one that meets fewest. Returns (offset (2,), anchor)."""
    marks = np.asarray(marks_xyz, dtype=float).reshape(-1, 3)
    boxes = [np.array([x - DOT_RADIUS, x + DOT_RADIUS, y - DOT_RADIUS, y + DOT_RADIUS])
             for x, y in marks[:, :2]]
    boxes += [label_box(p[:2] + offset[:2], anchor, MARK_LABEL_WIDTH)
              for p, (offset, anchor) in zip(marks, label_places(marks), strict=True)]
    return clear_place(end_xy, NAME_CHAR * len(name), np.array(boxes), places)


def hits(box: FloatArray, taken: NDArray) -> int:
    """How many of the boxes ``taken`` (K, 4) the box (x0, x1, y0, y1) meets."""
    taken = np.asarray(taken, dtype=float).reshape(-1, 4)
    return int(np.count_nonzero((taken[:, 1] > box[0]) & (taken[:, 0] < box[1])
                                & (taken[:, 3] > box[2]) & (taken[:, 2] < box[3])))


def clear_place(at_xy: NDArray[np.float64], width: float, taken: NDArray,
                places: tuple) -> tuple[NDArray[np.float64], str]:
    """The first of ``places`` ((offset (2,), anchor)) where a label ``width`` wide beside
    ``at_xy`` (2,) meets none of the boxes ``taken`` (K, 4) (x0, x1, y0, y1), else the one
    that meets fewest. Returns (offset (2,), anchor)."""
    met = []
    for offset, anchor in places:
        met.append(hits(label_box(np.asarray(at_xy, float) + offset, anchor, width), taken))
        if met[-1] == 0:
            break
    offset, anchor = places[int(np.argmin(met))]
    return np.asarray(offset, dtype=float), anchor


def end_places(tangent_xy: NDArray[np.float64], gap: float = 0.03) -> tuple:
    """Where a label may go beside a vessel's distal end on the model (offset (2,),
    anchor), first beyond the end along its direction ``tangent_xy`` (2,) (the text
    running away from the vessel), then round it, twice as far out at the last."""
    d = np.asarray(tangent_xy, dtype=float)
    d = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-12 else np.array([1.0, 0.0])
    if abs(d[1]) > 2.0 * abs(d[0]):  # up or down the screen: the text centred on it
        first = (gap * d, "bottom-center" if d[1] < 0 else "top-center")
    else:
        first = (gap * d, "center-left" if d[0] >= 0 else "center-right")
    round_it = tuple((offset * 3.0, anchor) for offset, anchor in NAME_PLACES)
    return (first, *round_it, *((offset * 2.0, anchor) for offset, anchor in round_it))


#: Where the MLD's name may go: beside it, then a little further out when marks crowd it.
MLD_PLACES = NAME_PLACES + tuple((offset * 3.0, anchor) for offset, anchor in NAME_PLACES)
