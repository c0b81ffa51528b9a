"""What the viewer draws in viser's 3D scene.

Both angiograms side by side as image planes (view A left, view B right)
with their marks, labels, epipolar lines, traces and back-projections on
overlay frames placed exactly over the images; the reconstructed mesh and
3D centerline above them; camera framing; and the conversion of a clicked
ray to an image pixel.

Scene layout (viser world units; the scene's up direction is -y so that the
image rows run downwards on screen and the camera looks along +z):

- ``/view_a``, ``/view_b``: image planes, longer side :data:`IMAGE_SIZE`
  units, node-local x along the columns and y down the rows; they are the
  only clickable nodes;
- ``/over_a``, ``/over_b``: frames at the same place as the images holding
  every overlay (same local coordinates). The overlays are deliberately NOT
  children of the clickable images: the browser's ray test hits a point
  cloud from far away (three.js' point threshold is in world units) and a
  hit on a child counts as a click on its parent, so marks drawn under
  ``/view_b`` caught clicks made on image A;
- ``/model``: the reconstruction, rotated into view A's frame (so it first
  looks like view A) and scaled to :data:`MODEL_SIZE` units, above the images.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import viser
from numpy.typing import NDArray

from viewer_app.model_colours import diameter_colors, segment_diameter_colors
from viewer_app.placing import MLD_PLACES, label_places, name_place
from viewer_app.results import angle_text

if TYPE_CHECKING:
    from recon.pipeline import Reconstruction
    from recon.types import Angiogram
    from viewer_app.state import MarkState

__all__ = [
    "IMAGE_SIZE",
    "IMAGE_GAP",
    "MODEL_SIZE",
    "OVERLAY_Z",
    "View",
    "ViewNodes",
    "add_view_nodes",
    "clear_results",
    "draw_marks",
    "draw_flagged",
    "draw_catheters",
    "draw_refusal",
    "draw_reconstruction",
    "segment_title",
    "title_position",
    "model_placement",
    "diameter_colors",
    "lesion_points",
    "automatic_marks",
    "draw_lesion_marks",
    "ModelNodes",
    "LAYOUTS",
    "Framing",
    "apply_framing",
    "camera_distance",
    "camera_rotated_deg",
    "layout_framing",
    "zoom_framing",
    "ZOOMS",
    "set_visibility",
    "overlay_name",
    "ray_to_px",
    "update_image",
]

log = logging.getLogger(__name__)

IMAGE_SIZE = 1.0  # scene units of an image's longer side
IMAGE_GAP = 0.08  # between the two images
MODEL_SIZE = 1.0  # scene units of the model's longest extent
OVERLAY_Z = -0.002  # overlays a hair in front of the image plane (towards the camera)

KIND_COLORS = {
    "proximal": (40, 220, 60),
    "waypoint": (255, 210, 0),
    "distal": (240, 50, 50),
    "feature": (0, 200, 255),
}
EPIPOLAR_COLOR = (255, 0, 255)
TRACE_COLOR = (255, 140, 0)
MESH_COLOR = (205, 70, 70, 255)
BACKPROJ_COLOR = (0, 255, 160)
FLAGGED_COLOR = (255, 30, 30)  # stretches the cross-view consistency check flagged
CATHETER_COLOR = (150, 190, 255)  # the guiding catheter found, dashed
CATHETER_DASH_PX = 6.0  # dash and gap length along it

FloatArray = NDArray[np.float64]


def rgb_from_image(image: NDArray, level: float, width: float) -> NDArray[np.uint8]:
    """Window/level a raw (H, W) image to an RGB uint8 (H, W, 3) array."""
    lo = level - width / 2.0
    grey = np.clip((image.astype(np.float32) - lo) / max(width, 1e-6), 0.0, 1.0)
    g8 = (grey * 255.0 + 0.5).astype(np.uint8)
    return np.repeat(g8[:, :, None], 3, axis=2)


def default_window(image: NDArray) -> tuple[float, float]:
    """(level, width) spanning the 0.5-99.5 percentiles of the image."""
    lo, hi = np.percentile(image, [0.5, 99.5])
    if hi <= lo:
        hi = lo + 1.0
    return float((lo + hi) / 2.0), float(hi - lo)


def polyline_segments(points: FloatArray) -> FloatArray:
    """(N, 3) polyline -> (N - 1, 2, 3) segments."""
    p = np.asarray(points, dtype=float)
    if len(p) < 2:
        return np.zeros((0, 2, 3))
    return np.stack([p[:-1], p[1:]], axis=1)


@dataclass
class ViewNodes:
    """The scene nodes of one view: the image plane and its overlays (children of the image)."""

    image: viser.ImageHandle
    root: viser.FrameHandle  # /over_<key>: parent of every overlay
    marks: viser.PointCloudHandle
    selected: viser.PointCloudHandle
    epipolar: viser.LineSegmentsHandle
    trace: viser.LineSegmentsHandle
    backproj: viser.LineSegmentsHandle
    title: viser.LabelHandle
    labels: list[viser.LabelHandle] = field(default_factory=list)  # one per mark


class View:
    """One angiogram as shown: the loaded run, display window, scene nodes, vesselness."""

    nodes: ViewNodes  # set by add_view_nodes

    def __init__(self, key: str, angio: Angiogram, display_name: str) -> None:
        self.key = key
        self.angio = angio
        self.display_name = display_name
        self.level, self.width = default_window(angio.image)
        self.vesselness: object | None = None
        self.vesselness_lock = threading.Lock()
        rows, cols = angio.image.shape
        scale = IMAGE_SIZE / max(rows, cols)
        self.render_w, self.render_h = cols * scale, rows * scale
        x = (self.render_w if key == "b" else -self.render_w) / 2 + (
            IMAGE_GAP / 2 if key == "b" else -IMAGE_GAP / 2
        )
        self.position = np.array([x, 0.0, 0.0])

    @property
    def rows(self) -> int:
        return int(self.angio.image.shape[0])

    @property
    def cols(self) -> int:
        return int(self.angio.image.shape[1])

    def local_from_px(self, points_px: FloatArray, z: float = OVERLAY_Z) -> FloatArray:
        """Pixels (N, 2) (col, row) -> node-local points (N, 3)."""
        p = np.asarray(points_px, dtype=float).reshape(-1, 2)
        x = (p[:, 0] + 0.5) / self.cols * self.render_w - self.render_w / 2
        y = (p[:, 1] + 0.5) / self.rows * self.render_h - self.render_h / 2
        return np.column_stack([x, y, np.full(len(p), z)])

    def px_from_local(self, xy: FloatArray) -> FloatArray:
        """Node-local (x, y) -> pixel (col, row)."""
        col = (xy[0] + self.render_w / 2) / self.render_w * self.cols - 0.5
        row = (xy[1] + self.render_h / 2) / self.render_h * self.rows - 0.5
        return np.array([col, row])

    def get_vesselness(self) -> object:
        """Vesselness of the current frame, computed once (recon.trace.centerline)."""
        from recon.trace.centerline import compute_vesselness

        with self.vesselness_lock:
            if self.vesselness is None:
                self.vesselness = compute_vesselness(
                    self.angio.image, pixel_mm=self.angio.geometry.pixel_mm_at_isocenter
                )
            return self.vesselness


def overlay_name(key: str) -> str:
    """Scene path of the overlay frame of view ``key`` (see the module docstring)."""
    return f"/over_{key}"


def add_view_nodes(scene: viser.SceneApi, v: View, on_click: Callable,
                   on_drag: Callable | None = None) -> ViewNodes:
    """Add ``/view_<key>`` (the image, clicks go to ``on_click``, left drags to
    ``on_drag``: the image takes them, the camera does not turn) and its empty overlays
    under ``/over_<key>``; the overlays of a previous pair are removed first."""
    image_name, name = f"/view_{v.key}", overlay_name(v.key)
    scene.remove_by_name(name)  # and every child: marks, labels, results of the old pair
    image = scene.add_image(
        image_name,
        rgb_from_image(v.angio.image, v.level, v.width),
        v.render_w,
        v.render_h,
        position=tuple(v.position),
        format="jpeg",
        jpeg_quality=90,
        cast_shadow=False,
        receive_shadow=False,
    )
    image.on_click(on_click)
    if on_drag is not None:
        image.on_drag(on_drag)
    root = scene.add_frame(name, show_axes=False, position=tuple(v.position))
    empty_pts = np.zeros((0, 3), np.float32)
    empty_seg = np.zeros((0, 2, 3), np.float32)
    marks = scene.add_point_cloud(
        f"{name}/marks", empty_pts, (255, 255, 255), point_size=0.016,
        point_shape="circle", point_shading="flat")
    selected = scene.add_point_cloud(
        f"{name}/selected", empty_pts, (255, 255, 255), point_size=0.028,
        point_shape="circle", point_shading="flat")
    epipolar = scene.add_line_segments(
        f"{name}/epipolar", empty_seg, EPIPOLAR_COLOR, thickness=2.5,
        thickness_units="screen")
    trace = scene.add_line_segments(
        f"{name}/trace", empty_seg, TRACE_COLOR, thickness=2.0, thickness_units="screen")
    backproj = scene.add_line_segments(
        f"{name}/backproj", empty_seg, BACKPROJ_COLOR, thickness=2.0,
        thickness_units="screen")
    g = v.angio.geometry
    title = scene.add_label(
        f"{name}/title",
        f"{v.key.upper()}: {v.display_name} — {angle_text(g.alpha_deg, g.beta_deg)}",
        position=(-v.render_w / 2, -v.render_h / 2 - 0.02, 0.0),
        anchor="bottom-left",
    )
    v.nodes = ViewNodes(image=image, root=root, marks=marks, selected=selected, epipolar=epipolar,
                        trace=trace, backproj=backproj, title=title)
    return v.nodes


def ray_to_px(v: View, origin: tuple, direction: tuple) -> FloatArray | None:
    """Intersect a world ray with the (unrotated) image plane -> pixel (col, row)."""
    o, d = np.asarray(origin, float), np.asarray(direction, float)
    if abs(d[2]) < 1e-12:
        return None
    t = (v.position[2] - o[2]) / d[2]
    hit = o + t * d - v.position
    return v.px_from_local(hit[:2])


def update_image(v: View) -> None:
    """Redraw the image plane after a change of frame or window."""
    v.nodes.image.image = rgb_from_image(v.angio.image, v.level, v.width)


def draw_marks(scene: viser.SceneApi, views: Mapping[str, View], st: MarkState) -> None:
    """Marks, labels, selection and the epipolar line of the selected mark."""
    sel = st.selected
    epi = st.epipolar_segment()
    for v in views.values():
        marks = st.marks_in(v.key)
        pts = v.local_from_px(np.array([m.point_px for m in marks]).reshape(-1, 2))
        v.nodes.marks.points = pts.astype(np.float32)
        v.nodes.marks.colors = np.array(
            [KIND_COLORS[m.kind] for m in marks], np.uint8).reshape(-1, 3)
        sel_pts = (v.local_from_px(np.array([sel.point_px]), z=OVERLAY_Z / 2)
                   if sel is not None and sel.view == v.key else np.zeros((0, 3)))
        v.nodes.selected.points = sel_pts.astype(np.float32)
        for h in v.nodes.labels:
            h.remove()
        v.nodes.labels = [
            scene.add_label(f"{overlay_name(v.key)}/labels/m{m.id}", st.label(m),
                            position=tuple(p + offset), anchor=anchor, font_screen_scale=0.8)
            for m, p, (offset, anchor) in zip(marks, pts, label_places(pts), strict=True)
        ]
        if epi is not None and epi[0] == v.key:
            seg = v.local_from_px(epi[1], z=OVERLAY_Z * 1.5)[None]
        else:
            seg = np.zeros((0, 2, 3))
        v.nodes.epipolar.points = seg.astype(np.float32)


def clear_results(scene: viser.SceneApi, views: Mapping[str, View]) -> None:
    """Remove the traces, back-projections and the ``/model`` of a previous reconstruction."""
    for v in views.values():
        v.nodes.trace.points = np.zeros((0, 2, 3), np.float32)
        v.nodes.backproj.points = np.zeros((0, 2, 3), np.float32)
    _remove(scene, ["/model"] + [f"{overlay_name(k)}/{n}" for k in views
                                 for n in ("flagged", "flag_labels", "lesion", "lesion_labels",
                                           "branches", "catheter", "catheter_label")])
    draw_refusal(scene, views, None)


def _remove(scene: viser.SceneApi, names: list[str]) -> None:
    """Remove the scene nodes ``names`` (a name with no node is skipped)."""
    for name in names:
        try:
            scene.remove_by_name(name)
        except Exception:
            log.debug("nothing to remove at %s", name, exc_info=True)


@dataclass(frozen=True)
class ModelNodes:
    """The ``/model`` frame, where it sits (scene units) and how world mm map to it."""

    root: viser.FrameHandle
    position: FloatArray  # (3,) centre of the model
    T_scene_from_world: FloatArray  # (4, 4) similarity: world mm -> scene units


def draw_lesion_marks(scene: viser.SceneApi, views: Mapping[str, View], rec: Reconstruction,
                      model: ModelNodes, marks_s_mm: Mapping[str, float],
                      mld_mm: float) -> None:
    """MLD and lesion ends on both angiograms (projected) and the MLD on the model."""
    pts = lesion_points(rec, marks_s_mm)
    names = list(pts)
    scene.remove_by_name("/model/lesions")  # the other lesions' of the branch shown before
    P = np.array([pts[n] for n in names])
    for key, geom in (("a", rec.view_a), ("b", rec.view_b)):
        v, root = views[key], overlay_name(key)
        scene.remove_by_name(f"{root}/lesion_labels")
        local = v.local_from_px(geom.project(P), z=OVERLAY_Z * 1.8)
        scene.add_point_cloud(f"{root}/lesion", local.astype(np.float32),
                              np.array([MARKER_COLORS.get(n, MARKER_COLORS["MLD"])
                                        for n in names], np.uint8),
                              point_size=0.018, point_shape="diamond", point_shading="flat")
        # Only the MLDs are named (the other lesions' as L2, L3, ...): the lesion ends
        # (blue) sit a few mm from them and their names would cover the vessel. A name
        # goes where it clears the marks and their labels ("MLD" printed over "F2").
        for k, name in enumerate(names):
            if name in ("lesion start", "lesion end"):
                continue
            p = local[k]
            offset, anchor = name_place(p[:2], name, v.nodes.marks.points, MLD_PLACES)
            scene.add_label(f"{root}/lesion_labels/{name.replace(' ', '_').lower()}", name,
                            font_screen_scale=0.8, position=(*(p[:2] + offset), p[2]),
                            anchor=anchor)
    T = model.T_scene_from_world
    for name in names:  # the other lesions' MLDs on the model, smaller
        if name not in ("MLD", "lesion start", "lesion end"):
            at = T[:3, :3] @ pts[name] + T[:3, 3]
            scene.add_icosphere(f"/model/lesions/{name}", radius=0.014,
                                color=MARKER_COLORS["MLD"], position=tuple(at),
                                cast_shadow=False, receive_shadow=False)
            scene.add_label(f"/model/lesions/{name}_label", name,
                            position=tuple(at + np.array([0.025, 0.0, -0.03])),
                            anchor="center-left")
    mld_scene = T[:3, :3] @ pts["MLD"] + T[:3, 3]
    scene.add_icosphere("/model/mld", radius=0.02, color=MARKER_COLORS["MLD"],
                        position=tuple(mld_scene), cast_shadow=False, receive_shadow=False)
    scene.add_label("/model/mld_label", f"MLD {mld_mm:.2f} mm",
                    position=tuple(mld_scene + np.array([0.03, 0.0, -0.03])),
                    anchor="center-left")


def lesion_points(rec: Reconstruction, marks_s_mm: Mapping[str, float]) -> dict[str, FloatArray]:
    """World points (3,) at arc lengths ``marks_s_mm`` ({"MLD": s, "lesion start": s, ...})
    along the 3D centerline."""
    X = np.asarray(rec.centerline_3d.X_world, dtype=float)
    s = np.asarray(rec.centerline_3d.s_mm, dtype=float)
    return {n: np.array([np.interp(v, s, X[:, k]) for k in range(3)])
            for n, v in marks_s_mm.items()}


def automatic_marks(rec: Reconstruction) -> dict[str, float]:
    """Arc lengths (mm) of the MLD and, when a lesion was found, of its two ends; and the
    MLD of every other lesion (recon.lumen.lesions), named "L2", "L3", ... by number."""
    m = rec.measurements
    out = {"MLD": float(m.mld_s_mm)}
    if m.has_lesion:
        out["lesion start"] = float(m.lesion_start_s_mm)
        out["lesion end"] = float(m.lesion_end_s_mm)
    report = getattr(rec, "lesions", None)
    for k, les in enumerate(getattr(report, "lesions", ())):
        if k != report.primary:
            out[f"L{les.number}"] = float(les.narrowing.mld_s_mm)
    return out


MARKER_COLORS = {"MLD": (255, 0, 200), "lesion start": (0, 120, 255), "lesion end": (0, 120, 255)}


def model_placement(V_world: FloatArray, R_view_from_world: FloatArray,
                    views: Mapping[str, View]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Where the model of points ``V_world`` (N, 3) (mm) goes in the scene.

    In view A's frame (x = columns, y = rows, z = away from the source; its
    ``R_view_from_world``), so the first look at it matches view A; scaled to
    MODEL_SIZE, above the images. Returns ``T_scene_from_world`` (4, 4), the
    centre of its box on the images' plane (3,) and the centre of the model (3,).
    """
    V_view = np.asarray(V_world, dtype=float) @ R_view_from_world.T  # mm, view A's axes
    lo, hi = V_view.min(axis=0), V_view.max(axis=0)
    scale = MODEL_SIZE / max(float(np.max((hi - lo)[:2])), 1e-6)
    image_top = -max(v.render_h for v in views.values()) / 2
    model_position = np.array([0.0, image_top - 0.12 - MODEL_SIZE / 2, 0.0])
    T = np.eye(4)
    T[:3, :3] = scale * R_view_from_world
    T[:3, 3] = model_position - scale * (lo + hi) / 2
    # Its nearest point on the images' plane, the rest behind it: perspective then
    # makes no part larger than the framing allows (nothing cut off at the top).
    T[2, 3] = model_position[2] - scale * lo[2]
    centre = model_position + np.array([0.0, 0.0, scale * (hi[2] - lo[2]) / 2])
    return T, model_position, centre


def segment_title(rec: Reconstruction) -> str:
    """The line over a segment's model coloured by diameter."""
    return (f"3D model, {rec.measurements.segment_length_mm:.1f} mm; drag to rotate\n"
            "green = reference diameter, red = half of it")


def title_position(centre: FloatArray) -> tuple[float, float, float]:
    """Where the model's title goes: centred over it (the notifications, top left, would
    cover a left-aligned title), a line above its box (its top end reaches the box's
    edge); ``centre``: ModelNodes.position."""
    return float(centre[0]), float(centre[1]) - MODEL_SIZE / 2 - 0.04, 0.0


def draw_reconstruction(
    scene: viser.SceneApi, views: Mapping[str, View], rec: Reconstruction
) -> ModelNodes:
    """Traces, back-projections, MLD and lesion ends on the images; the mesh coloured by
    lumen diameter with the MLD marked, and the 3D centerline, above the images."""
    draw_refusal(scene, views, None)  # a reconstruction replaces a refusal's ring
    X = np.asarray(rec.centerline_3d.X_world, dtype=float)
    for key, cl, geom in (("a", rec.centerline_a, rec.view_a), ("b", rec.centerline_b,
                                                                rec.view_b)):
        v = views[key]
        v.nodes.trace.points = polyline_segments(
            v.local_from_px(cl.points_px, z=OVERLAY_Z * 0.8)).astype(np.float32)
        v.nodes.backproj.points = polyline_segments(
            v.local_from_px(geom.project(X), z=OVERLAY_Z * 1.2)).astype(np.float32)
    draw_flagged(scene, views, rec)
    draw_catheters(scene, views, rec)
    mesh = rec.surface.mesh.copy()
    T, _, centre = model_placement(np.asarray(mesh.vertices), rec.view_a.R_view_from_world,
                                   views)
    colors = segment_diameter_colors(rec, np.asarray(mesh.vertices))
    mesh.apply_transform(T)
    mesh.visual.vertex_colors = np.column_stack([colors, np.full(len(colors), 255, np.uint8)])
    root = scene.add_frame("/model", show_axes=False)
    scene.add_mesh_trimesh("/model/mesh", mesh, cast_shadow=False, receive_shadow=False)
    X_scene = X @ T[:3, :3].T + T[:3, 3]
    scene.add_line_segments("/model/centerline", polyline_segments(X_scene).astype(
        np.float32), (40, 40, 40), thickness=1.5, thickness_units="screen")
    m = rec.measurements
    scene.add_label("/model/title", segment_title(rec), position=title_position(centre),
                    anchor="top-center")
    model = ModelNodes(root=root, position=centre, T_scene_from_world=T)
    draw_lesion_marks(scene, views, rec, model, automatic_marks(rec), m.mld_mm)
    return model


def draw_flagged(scene: viser.SceneApi, views: Mapping[str, View], rec: Reconstruction
                 ) -> int:
    """The stretches the cross-view consistency check flagged, in FLAGGED_COLOR on both
    images (the 3D stretch projected), with a short label on the view it names; every
    branch's of a tree (recon.tree.TreeReconstruction). Returns the number of stretches
    drawn."""
    # every part's flagged 3D stretches (points (K, 3)), with the part they lie on
    flagged = []
    for part in tuple(getattr(rec, "branches", (rec,))):
        X = np.asarray(part.centerline_3d.X_world, dtype=float)
        s = np.asarray(part.centerline_3d.s_mm, dtype=float)
        for st in tuple(getattr(getattr(part, "consistency", None), "stretches", ())):
            keep = (s >= st.start_mm - 1e-6) & (s <= st.end_mm + 1e-6)
            flagged.append((part, st, X[keep]))
    for key in ("a", "b"):
        v = views[key]
        segments = [polyline_segments(v.local_from_px(
            (part.view_a if key == "a" else part.view_b).project(X_st), z=OVERLAY_Z * 1.4))
            for part, _, X_st in flagged if len(X_st) >= 2]
        named = [st for _, st, _ in flagged if st.view == key]
        seg = np.concatenate(segments) if segments else np.zeros((0, 2, 3))
        scene.add_line_segments(f"{overlay_name(key)}/flagged", seg.astype(np.float32),
                                FLAGGED_COLOR, thickness=5.0, thickness_units="screen")
        for i, st in enumerate(named):
            p = v.local_from_px(np.array([st.middle_px]), z=OVERLAY_Z * 1.6)[0]
            scene.add_label(f"{overlay_name(key)}/flag_labels/s{i}",
                            f"⚠ {st.kind.replace('_', ' ')} {st.start_mm:.0f}-{st.end_mm:.0f} mm",
                            position=tuple(p + np.array([0.01, -0.01, 0.0])),
                            anchor="bottom-left", font_screen_scale=0.8)
    return len(flagged)


def draw_catheters(scene: viser.SceneApi, views: Mapping[str, View], rec: Reconstruction
                   ) -> int:
    """The guiding catheter found in each view (recon.trace.guide_catheter), dashed in
    CATHETER_COLOR and labelled, so the clinician sees what the trace was kept off; a
    tree's first branch carries them. Returns the number drawn."""
    part = tuple(getattr(rec, "branches", (rec,)))[0]
    drawn = 0
    for key, cl in (("a", part.centerline_a), ("b", part.centerline_b)):
        v = views[key]
        dashes = []
        for pts in cl.catheters_px:
            s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
            s_fine = np.arange(0.0, s[-1], CATHETER_DASH_PX)
            dense = np.column_stack([np.interp(s_fine, s, pts[:, j]) for j in (0, 1)])
            seg = polyline_segments(v.local_from_px(dense, z=OVERLAY_Z * 0.9))
            dashes.append(seg[::2])
        seg = np.concatenate(dashes) if dashes else np.zeros((0, 2, 3))
        scene.add_line_segments(f"{overlay_name(key)}/catheter", seg.astype(np.float32),
                                CATHETER_COLOR, thickness=2.0, thickness_units="screen")
        if cl.catheters_px:  # a quarter of the way in from the field's edge: its tip
            pts = cl.catheters_px[0]  # lies at the ostium, among the marks' labels
            at = v.local_from_px(pts[len(pts) // 4][None], z=OVERLAY_Z * 1.6)[0]
            scene.add_label(f"{overlay_name(key)}/catheter_label", "catheter (not traced)",
                            position=tuple(at + np.array([0.01, 0.0, 0.0])),
                            anchor="center-left", font_screen_scale=0.7)
        drawn += len(cl.catheters_px)
    return drawn


#: The ring round the place a refused trace names: this fraction of the image's longer
#: side, at least REFUSAL_MIN_PX.
REFUSAL_RING = 0.03
REFUSAL_MIN_PX = 10.0


def draw_refusal(scene: viser.SceneApi, views: Mapping[str, View], error: object | None
                 ) -> bool:
    """A ring in FLAGGED_COLOR round the place a refused trace names (a
    :class:`~recon.trace.trace_error.TraceError`'s ``view`` and ``near_px``: where a waypoint
    would help), labelled, on that view; ``error`` None removes it. An error that names
    no place changes nothing. Returns whether a place was drawn."""
    if error is None:
        _remove(scene, [f"{overlay_name(key)}/{name}" for key in views
                        for name in ("refusal", "refusal_label")])
        return False
    key = str(getattr(error, "view", None) or "").lower()
    near = getattr(error, "near_px", None)
    if key not in views or near is None:
        return False
    draw_refusal(scene, views, None)
    v = views[key]
    radius_px = max(REFUSAL_RING * max(v.cols, v.rows), REFUSAL_MIN_PX)
    t = np.linspace(0.0, 2.0 * np.pi, 49)
    ring_px = np.asarray(near, float)[None, :] + radius_px * np.column_stack([np.cos(t),
                                                                               np.sin(t)])
    ring = polyline_segments(v.local_from_px(ring_px, z=OVERLAY_Z * 1.6))
    scene.add_line_segments(f"{overlay_name(key)}/refusal", ring.astype(np.float32),
                            FLAGGED_COLOR, thickness=4.0, thickness_units="screen")
    top = v.local_from_px(np.asarray(near, float)[None, :] + [radius_px, -radius_px],
                          z=OVERLAY_Z * 1.6)[0]
    scene.add_label(f"{overlay_name(key)}/refusal_label", "⚠ trace refused here",
                    position=tuple(top), anchor="bottom-left", font_screen_scale=0.8)
    return True


CAMERA_FOV_RAD = float(np.radians(75.0))  # viser's default vertical field of view
STRAIGHT = np.array([0.0, 0.0, 1.0])  # camera looks along +z, rows down the screen
ROTATED_DEG = 4.0  # a camera turned further than this from STRAIGHT was rotated by the user

LAYOUTS: tuple[str, ...] = ("Angiograms", "Angiograms + 3D", "3D model")


@dataclass(frozen=True)
class Framing:
    """What a layout shows and where the camera looks (scene units)."""

    images: bool
    model: bool
    centre: FloatArray  # (3,) look-at point
    half_w: float  # half width and height of the content to fit
    half_h: float
    straight: bool  # camera straight at the images (else: keep the user's direction)
    near: float = 0.0  # how far the content reaches from the centre towards the camera


def layout_framing(layout: str, views: Mapping[str, View],
                   model_position: FloatArray | None) -> Framing:
    """The framing of a layout ("Angiograms", "Angiograms + 3D", "3D model"); without a
    model every layout shows the angiograms."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")
    a, b = views["a"], views["b"]
    left = a.position[0] - a.render_w / 2
    right = b.position[0] + b.render_w / 2
    half_h = max(a.render_h, b.render_h) / 2
    images_centre = np.array([(left + right) / 2, 0.0, 0.0])
    half_w = (right - left) / 2
    if model_position is None or layout == "Angiograms":
        return Framing(True, False, images_centre, half_w,
                       half_h + 0.04, True)
    if layout == "3D model":  # the model's nearest point lies on the images' plane (z 0)
        centre = np.asarray(model_position, float)
        return Framing(False, True, centre, MODEL_SIZE * 0.75, MODEL_SIZE * 0.75, False,
                       near=max(float(centre[2]), 0.0))
    top = float(model_position[1]) - MODEL_SIZE / 2
    centre = np.array([images_centre[0], (top + half_h) / 2, 0.0])
    return Framing(True, True, centre, half_w, (half_h - top) / 2 + 0.04, True)


#: The zoom factors offered: the image's magnification against the "Angiograms" layout.
ZOOMS: tuple[int, ...] = (2, 4, 8)


def zoom_framing(views: Mapping[str, View], key: str, point_px: tuple[float, float],
                 factor: float) -> Framing:
    """Straight on image ``key`` ("a" or "b"), magnified ``factor`` times against the
    "Angiograms" layout and centred on its pixel ``point_px`` (col, row): a close look at
    one place of one image (the guiding catheter's edges, a mark), the other image aside."""
    both = layout_framing("Angiograms", views, None)
    v = views[key]
    centre = v.position + v.local_from_px(np.asarray(point_px, dtype=float)[None], z=0.0)[0]
    return Framing(True, False, centre, both.half_w / factor, both.half_h / factor, True)


def camera_distance(fr: Framing, aspect: float, fov_rad: float = CAMERA_FOV_RAD) -> float:
    """Distance at which a camera of vertical field of view ``fov_rad`` and the given
    aspect (width / height) shows the framing's content whole."""
    t = float(np.tan(fov_rad / 2))  # (the content's near side, not its centre, must fit)
    return 1.06 * max(fr.half_h / t, fr.half_w / (t * max(aspect, 0.2))) + fr.near


def apply_framing(client: viser.ClientHandle, fr: Framing) -> None:
    """Set one client's camera to the framing (straight, or keeping its direction)."""
    cam = client.camera
    direction = STRAIGHT
    if not fr.straight:
        d = np.asarray(cam.look_at, float) - np.asarray(cam.position, float)
        if np.linalg.norm(d) > 1e-9:
            direction = d / np.linalg.norm(d)
    dist = camera_distance(fr, float(cam.aspect or 1.0), float(cam.fov or CAMERA_FOV_RAD))
    with client.atomic():
        cam.up_direction = (0.0, -1.0, 0.0)
        # viser moves look_at along with a new position: position first, then look_at.
        cam.position = tuple(fr.centre - direction * dist)
        cam.look_at = tuple(fr.centre)


def set_visibility(views: Mapping[str, View], model: viser.FrameHandle | None,
                   fr: Framing) -> None:
    """Show or hide the image planes with their overlays, and the model."""
    for v in views.values():
        v.nodes.image.visible = fr.images
        v.nodes.root.visible = fr.images
    if model is not None:
        model.visible = fr.model


def camera_rotated_deg(client: viser.ClientHandle) -> float:
    """Angle between a client's viewing direction and the straight view (degrees)."""
    cam = client.camera
    d = np.asarray(cam.look_at, float) - np.asarray(cam.position, float)
    n = float(np.linalg.norm(d))
    if n < 1e-9:
        return 0.0
    return float(np.degrees(np.arccos(np.clip(d @ STRAIGHT / n, -1.0, 1.0))))
