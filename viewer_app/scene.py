"""What the viewer draws in viser's 3D scene.

Both angiograms side by side as image planes (view A left, view B right)
with their marks, labels, epipolar lines, traces and back-projections as
children of the image nodes; the reconstructed mesh and 3D centerline above
them; camera framing; and the conversion of a clicked ray to an image pixel.

Scene layout (viser world units; the scene's up direction is -y so that the
image rows run downwards on screen and the camera looks along +z):

- ``/view_a``, ``/view_b``: image planes, longer side :data:`IMAGE_SIZE`
  units, node-local x along the columns and y down the rows;
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

from viewer_app.results import angle_text

if TYPE_CHECKING:
    from recon.pipeline import Reconstruction
    from recon.types import Angiogram
    from viewer_app.state import MarkState

__all__ = [
    "IMAGE_SIZE",
    "IMAGE_GAP",
    "MODEL_SIZE",
    "PANEL_SHIFT",
    "OVERLAY_Z",
    "View",
    "ViewNodes",
    "add_view_nodes",
    "clear_results",
    "draw_marks",
    "draw_flagged",
    "draw_reconstruction",
    "frame_camera_on",
    "ray_to_px",
    "update_image",
    "view_all",
]

log = logging.getLogger(__name__)

IMAGE_SIZE = 1.0  # scene units of an image's longer side
IMAGE_GAP = 0.08  # between the two images
MODEL_SIZE = 1.0  # scene units of the model's longest extent
PANEL_SHIFT = 0.5  # camera x offset so the content sits left of the control panel
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
        """Vesselness of the current frame, computed once (recon.centerline)."""
        from recon.centerline import compute_vesselness

        with self.vesselness_lock:
            if self.vesselness is None:
                self.vesselness = compute_vesselness(
                    self.angio.image, pixel_mm=self.angio.geometry.pixel_mm_at_isocenter
                )
            return self.vesselness


def add_view_nodes(scene: viser.SceneApi, v: View, on_click: Callable) -> ViewNodes:
    """Add ``/view_<key>`` (the image, clicks go to ``on_click``) and its empty overlays."""
    name = f"/view_{v.key}"
    image = scene.add_image(
        name,
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
    v.nodes = ViewNodes(image=image, marks=marks, selected=selected, epipolar=epipolar,
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
            scene.add_label(
                f"/view_{v.key}/labels/m{m.id}", st.label(m),
                position=tuple(p + np.array([0.008, 0.008, 0.0])), anchor="top-left",
                font_screen_scale=0.8)
            for m, p in zip(marks, pts, strict=True)
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
    names = ["/model"] + [f"/view_{k}/{n}" for k in views for n in ("flagged", "flag_labels")]
    for name in names:
        try:
            scene.remove_by_name(name)
        except Exception:
            log.debug("nothing to remove at %s", name, exc_info=True)


def draw_reconstruction(
    scene: viser.SceneApi, views: Mapping[str, View], rec: Reconstruction
) -> FloatArray:
    """Traces and back-projections on the images, mesh + 3D centerline; returns the model's
    position (scene units)."""
    X = np.asarray(rec.centerline_3d.X_world, dtype=float)
    for key, cl, geom in (("a", rec.centerline_a, rec.view_a), ("b", rec.centerline_b,
                                                                rec.view_b)):
        v = views[key]
        v.nodes.trace.points = polyline_segments(
            v.local_from_px(cl.points_px, z=OVERLAY_Z * 0.8)).astype(np.float32)
        v.nodes.backproj.points = polyline_segments(
            v.local_from_px(geom.project(X), z=OVERLAY_Z * 1.2)).astype(np.float32)
    draw_flagged(scene, views, rec)
    # The model in view A's frame (x = columns, y = rows, z = away from the source),
    # so the first look at it matches view A; scaled to MODEL_SIZE, above the images.
    R = rec.view_a.R_view_from_world
    mesh = rec.surface.mesh.copy()
    V_view = np.asarray(mesh.vertices) @ R.T  # mm, view A's (u, v, d) axes
    lo, hi = V_view.min(axis=0), V_view.max(axis=0)
    scale = MODEL_SIZE / max(float(np.max((hi - lo)[:2])), 1e-6)
    image_top = -max(v.render_h for v in views.values()) / 2
    model_position = np.array([0.0, image_top - 0.12 - MODEL_SIZE / 2, 0.0])
    T = np.eye(4)
    T[:3, :3] = scale * R
    T[:3, 3] = model_position - scale * (lo + hi) / 2
    mesh.apply_transform(T)
    mesh.visual.face_colors = MESH_COLOR
    scene.add_mesh_trimesh("/model/mesh", mesh, cast_shadow=False, receive_shadow=False)
    X_scene = (X @ R.T) * scale + T[:3, 3]
    scene.add_line_segments("/model/centerline", polyline_segments(X_scene).astype(
        np.float32), (255, 220, 0), thickness=3.0, thickness_units="screen")
    scene.add_label("/model/title", f"3D: {rec.centerline_3d.length_mm:.1f} mm "
                    f"(view A orientation, drag to rotate)",
                    position=(-views["a"].render_w - IMAGE_GAP / 2,
                              model_position[1] - MODEL_SIZE / 2, 0.0),
                    anchor="top-left")
    return model_position


def draw_flagged(scene: viser.SceneApi, views: Mapping[str, View], rec: Reconstruction
                 ) -> int:
    """The stretches the cross-view consistency check flagged, in FLAGGED_COLOR on both
    images (the 3D stretch projected), with a short label on the view it names.
    Returns the number of stretches drawn."""
    consistency = getattr(rec, "consistency", None)
    stretches = tuple(getattr(consistency, "stretches", ()))
    X = np.asarray(rec.centerline_3d.X_world, dtype=float)
    s = np.asarray(rec.centerline_3d.s_mm, dtype=float)
    for key, geom in (("a", rec.view_a), ("b", rec.view_b)):
        v = views[key]
        segments = []
        for st in stretches:
            keep = (s >= st.start_mm - 1e-6) & (s <= st.end_mm + 1e-6)
            if keep.sum() >= 2:
                segments.append(polyline_segments(
                    v.local_from_px(geom.project(X[keep]), z=OVERLAY_Z * 1.4)))
        seg = np.concatenate(segments) if segments else np.zeros((0, 2, 3))
        scene.add_line_segments(f"/view_{key}/flagged", seg.astype(np.float32), FLAGGED_COLOR,
                                thickness=5.0, thickness_units="screen")
        for i, st in enumerate(st for st in stretches if st.view == key):
            p = v.local_from_px(np.array([st.middle_px]), z=OVERLAY_Z * 1.6)[0]
            scene.add_label(f"/view_{key}/flag_labels/s{i}",
                            f"⚠ {st.kind.replace('_', ' ')} {st.start_mm:.0f}-{st.end_mm:.0f} mm",
                            position=tuple(p + np.array([0.01, -0.01, 0.0])),
                            anchor="bottom-left", font_screen_scale=0.8)
    return len(stretches)


def frame_camera_on(server: viser.ViserServer, centre: FloatArray, size: float) -> None:
    """Point every client's camera at ``centre``, far enough back to show ``size`` units."""
    for c in server.get_clients().values():
        try:
            with c.atomic():
                c.camera.up_direction = (0.0, -1.0, 0.0)
                target = centre + [PANEL_SHIFT * size, 0.0, 0.0]
                c.camera.position = tuple(target + [0.0, 0.0, -1.5 * size])
                c.camera.look_at = tuple(target)
        except Exception:
            log.debug("camera framing failed", exc_info=True)


def view_all(server: viser.ViserServer) -> None:
    """Camera on both images and the model."""
    frame_camera_on(server, np.array([0.0, -0.62, 0.0]), 1.45)
