"""Where the distal FFR goes on the 3D model so that it covers no vessel and no other
label, in both straight views of the model: the whole page's ("Angiograms + 3D", seen
from far, nearly without perspective) and the model's alone ("3D model", seen from close
by: its deep parts draw towards its centre). Pure numpy; sizes in scene units (the model
is :data:`viewer_app.scene.MODEL_SIZE` tall, y grows down the screen).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from viewer_app.placing import LABEL_HEIGHT, end_places, hits, label_box
from viewer_app.scene import (
    CAMERA_FOV_RAD,
    MODEL_SIZE,
    Framing,
    automatic_marks,
    camera_distance,
    lesion_points,
    title_position,
)

if TYPE_CHECKING:
    from recon.pipeline import Reconstruction

__all__ = ["MODEL_CHAR", "distal_label_places"]

FloatArray = NDArray[np.float64]

#: A label on the model (viser's default size) per character, in scene units in the
#: "Angiograms + 3D" view (as placing.NAME_CHAR, for the larger font).
MODEL_CHAR = 0.015
ASPECT = 1.1  # the canvas beside the docked panel (as viewer_app.camera)

Projection = Callable[[FloatArray], FloatArray]  # scene points (N, 3) -> screen (N, 2)


def _views(centre: FloatArray) -> list[tuple[Projection, float]]:
    """The two straight views of a model whose centre is ``centre`` (ModelNodes.position;
    its z the model's half depth, its nearest point on the images' plane): each a
    projection of scene points to the images' plane as seen, and how large a label is
    there relative to the first view. The page's view is taken as orthographic (its
    camera is about 1.5 units away from a model 1 unit deep or less)."""
    centre = np.asarray(centre, float)
    t = float(np.tan(CAMERA_FOV_RAD / 2))
    page_half_h = ((0.5 - (centre[1] - MODEL_SIZE / 2)) / 2 + 0.04) * 1.06  # square images
    near = max(float(centre[2]), 0.0)
    fr = Framing(False, True, centre, MODEL_SIZE * 0.75, MODEL_SIZE * 0.75, False, near=near)
    to_plane = camera_distance(fr, ASPECT) - near  # the camera to the images' plane
    cam_z = centre[2] - near - to_plane

    def close(P: FloatArray) -> FloatArray:
        P = np.atleast_2d(np.asarray(P, float))
        return centre[:2] + (P[:, :2] - centre[:2]) * (to_plane / (P[:, 2] - cam_z))[:, None]

    def far(P: FloatArray) -> FloatArray:
        return np.atleast_2d(np.asarray(P, float))[:, :2]

    return [(far, 1.0), (close, to_plane * t / (page_half_h))]


def _label(view: tuple[Projection, float], at: FloatArray, anchor: str, chars: int,
           lines: int = 1) -> FloatArray:
    """The box of a label of ``lines`` lines of ``chars`` characters at the scene point
    ``at`` (3,)."""
    project, size = view
    return label_box(project(at)[0], anchor, MODEL_CHAR * chars * size,
                     LABEL_HEIGHT * lines * size)


def distal_label_places(parts: Sequence[Reconstruction], T: FloatArray, centre: FloatArray,
                        shown: int, texts: Sequence[str | None],
                        names: Sequence[str] | None = None, title: str = ""
                        ) -> list[tuple[tuple[float, float, float], str] | None]:
    """Where the label ``texts[k]`` (None: no label) goes at the distal end of part ``k``
    (a tree's branches or the one segment; T: world mm -> scene, ``centre``: the model's,
    ModelNodes.position): the first of :func:`viewer_app.placing.end_places` (beyond the
    end along the vessel, then round it) that in both straight views covers no vessel
    (each centerline widened by its radius), none of the labels already on the model
    (the MLD's and other lesions' of part ``shown``, the branches' ``names`` at their
    middles, the ``title`` over the model) and no label placed before it; else the one
    covering fewest. Returns per part (scene position (3,), anchor) or None."""
    views = _views(centre)
    scale = float(np.linalg.norm(T[:3, 0]))
    X_parts = [np.asarray(p.centerline_3d.X_world, float) @ T[:3, :3].T + T[:3, 3]
               for p in parts]
    taken: list[list[FloatArray]] = [[] for _ in views]
    for j, view in enumerate(views):
        for part, X in zip(parts, X_parts, strict=True):
            xy = view[0](X[::3])
            r = (np.asarray(part.centerline_3d.radius_mm, float)[::3] * scale + 0.005) * view[1]
            taken[j] += [np.array([x - q, x + q, y - q, y + q])
                         for (x, y), q in zip(xy, r, strict=True)]
        if title:  # as scene.title_position puts it
            rows = title.splitlines()
            taken[j].append(_label(view, np.array(title_position(centre)), "top-center",
                                   max(len(r) for r in rows), len(rows)))
        for k, name in enumerate(names or ()):  # at the middle, as highlight_branch puts it
            at = X_parts[k][len(X_parts[k]) // 2] + [0.025, 0.0, 0.0]
            taken[j].append(_label(view, at, "center-left", len(name)))
        rec = parts[shown]
        for name, P in lesion_points(rec, automatic_marks(rec)).items():
            if name not in ("lesion start", "lesion end"):  # as scene.draw_lesion_marks
                text = f"MLD {rec.measurements.mld_mm:.2f} mm" if name == "MLD" else name
                at = T[:3, :3] @ P + T[:3, 3] + [0.03 if name == "MLD" else 0.025, 0.0, -0.03]
                taken[j].append(_label(view, at, "center-left", len(text)))
    out: list[tuple[tuple[float, float, float], str] | None] = []
    for X, text in zip(X_parts, texts, strict=True):
        if text is None:
            out.append(None)
            continue
        back = X[max(0, len(X) - 1 - max(1, len(X) // 50))]  # the last 2 %: its direction
        best, best_hits = None, None
        for offset, anchor in end_places(X[-1, :2] - back[:2]):
            at = X[-1] + [offset[0], offset[1], 0.0]
            met = sum(hits(_label(v, at, anchor, len(text)), taken[j])
                      for j, v in enumerate(views))
            if best_hits is None or met < best_hits:
                best, best_hits = (at, anchor), met
            if met == 0:
                break
        at, anchor = best
        for j, view in enumerate(views):
            taken[j].append(_label(view, at, anchor, len(text)))
        out.append(((float(at[0]), float(at[1]), float(at[2])), anchor))
    return out
