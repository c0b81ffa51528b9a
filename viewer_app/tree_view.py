"""A reconstruction as the viewer runs and shows it: one segment, or a vessel tree.

Reconstruct runs ``reconstruct_pair`` on the current segment when the marks
hold one complete segment, and ``reconstruct_tree`` on all of them when they
hold several (both in a child process under the job's limits,
:mod:`recon.io.isolated`). A tree is drawn branch by branch, each in its own
colour of :data:`BRANCH_COLORS`: its back-projected 3D centerline (thick) over
its 2D trace (thin) on both images, named at its distal end; in 3D the tree's
one watertight mesh coloured by the nearest branch, each branch's centerline
in a darker shade of its colour. The branch shown (the one whose table and
chart the results panel holds) has the thicker lines, its MLD marked and its
part of the mesh in full colour (the others' paler).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
import viser
from numpy.typing import NDArray

from viewer_app.model_colours import (
    FFR_KEY_TEXT,
    ffr_colors,
    segment_diameter_colors,
    vertex_ffr,
)
from viewer_app.model_labels import distal_label_places
from viewer_app.placing import name_place
from viewer_app.scene import (
    MODEL_SIZE,
    OVERLAY_Z,
    ModelNodes,
    View,
    automatic_marks,
    clear_results,
    draw_catheters,
    draw_flagged,
    draw_lesion_marks,
    draw_reconstruction,
    draw_refusal,
    model_placement,
    overlay_name,
    polyline_segments,
    segment_title,
    title_position,
)

if TYPE_CHECKING:
    from recon.pipeline import Reconstruction
    from recon.seeds import Seeds
    from recon.tree import TreeReconstruction
    from viewer_app.state import MarkState

    Result = Reconstruction | TreeReconstruction

__all__ = [
    "BRANCH_COLORS",
    "branch_color",
    "branch_heading",
    "branch_names",
    "branches_of",
    "draw_result",
    "draw_out_of_date",
    "distal_ffr_text",
    "draw_tree",
    "ffr_title",
    "has_ffr",
    "paint_model",
    "highlight_branch",
    "is_tree",
    "marks_key",
    "mesh_colors",
    "name_place",
    "renamed",
    "run_reconstruction",
    "seeds_for_run",
    "summary_text",
    "tree_title",
]

#: (name, RGB) of the branches' colours, in segment order (then again from the first):
#: bright on a grey angiogram, and apart from the marks' green / yellow / red / cyan,
#: the magenta epipolar line and the red flagged stretches.
BRANCH_COLORS: tuple[tuple[str, tuple[int, int, int]], ...] = (
    ("orange", (255, 150, 40)),
    ("violet", (175, 115, 255)),
    ("aquamarine", (60, 230, 190)),
    ("pink", (255, 115, 190)),
    ("lime", (185, 235, 60)),
    ("sky blue", (110, 185, 255)),
)
FADE, FADE_TO = 0.6, (210, 210, 210)  # the mesh of the branches not shown: paler
CENTERLINE_SHADE = 0.55  # a branch's 3D centerline: its colour darkened to this fraction
THIN_PX, THICK_PX, SHOWN_PX = 1.2, 2.5, 4.5  # trace, back-projection, the shown branch's
def branch_color(k: int) -> tuple[int, int, int]:
    """RGB of branch (segment) ``k``."""
    return BRANCH_COLORS[k % len(BRANCH_COLORS)][1]


def _color_name(k: int) -> str:
    """The name of branch ``k``'s colour, as the page says it."""
    return BRANCH_COLORS[k % len(BRANCH_COLORS)][0]


def is_tree(result: object) -> bool:
    """Whether a result is a tree reconstruction (recon.tree.TreeReconstruction)."""
    return hasattr(result, "branches")


def branches_of(result: Result) -> tuple[Reconstruction, ...]:
    """A tree's branches (segment order), or the one segment's reconstruction."""
    return tuple(result.branches) if is_tree(result) else (result,)


def branch_names(result: Result) -> list[str]:
    """The segment names of a result's branches, in their order."""
    return [result.seeds.segments[b.options.segment].name for b in branches_of(result)]


def seeds_for_run(state: MarkState) -> tuple[Seeds, int]:
    """The complete marks as seeds and the current segment's index among them (0 when it
    is incomplete). Raises ValueError naming what is missing when none is complete."""
    seeds = state.to_seeds()
    if not seeds.segments:
        raise ValueError(f"marks: no complete segment yet ({'; '.join(state.missing()[:3])})")
    name = state.segment_names[state.current_segment]
    names = [s.name for s in seeds.segments]
    return seeds, names.index(name) if name in names else 0


def run_reconstruction(view_a: View, view_b: View, seeds: Seeds, segment: int,
                       intensity: Mapping[str, str],
                       limits: tuple[float | None, float | None],
                       progress: Callable[[str, float], None]) -> Result:
    """Reconstruct the marks in a child process under ``limits`` (memory GB, CPU s): the
    whole tree when ``seeds`` has several segments, else segment ``segment``. The viewer's
    options: matcher match3, PALM calibration, each view's stored-values choice
    (``intensity``: "a" / "b" -> lin, log or auto)."""
    from recon.io.isolated import run_isolated
    from recon.pipeline import ReconstructionOptions

    options = ReconstructionOptions(matcher="match3", optimizer="palm", segment=segment,
                                    intensity_a=intensity["a"], intensity_b=intensity["b"])
    maps = (view_a.get_vesselness(), view_b.get_vesselness())  # cached for snapping
    target = ("recon.io.isolated:reconstruct_tree_limited" if len(seeds.segments) > 1
              else "recon.io.isolated:reconstruct_limited")
    return run_isolated(target, (view_a.angio, view_b.angio, seeds, options, maps, *limits),
                        progress=progress)


def summary_text(result: Result) -> str:
    """The one line of the "Reconstructed" notification."""
    parts = branches_of(result)
    mesh = result.tree_surface.mesh if is_tree(result) else result.surface.mesh
    length_mm = sum(b.centerline_3d.length_mm for b in parts)
    what = f"{len(parts)} branches, {length_mm:.1f} mm of centerline" if is_tree(result) \
        else f"{length_mm:.1f} mm centerline"
    return (f"{what}, {len(mesh.faces)} faces, "
            f"{result.timings_ms.get('total', 0):.0f} ms")


def renamed(result: Result, before: list[str], after: list[str]) -> Result | None:
    """``result`` with its segment renamed as the marks' segment names went from ``before``
    to ``after`` (a Rename, or the undo of one: the same count, one name changed), in its
    seeds, its branches' seeds and its bifurcations; None when that is not the change, or
    the result has no segment of the old name."""
    changed = [(o, n) for o, n in zip(before, after, strict=False) if o != n]
    if len(before) != len(after) or len(changed) != 1:
        return None
    old, new = changed[0]
    if old not in [s.name for s in result.seeds.segments]:
        return None
    seeds = replace(result.seeds, segments=tuple(
        replace(s, name=new if s.name == old else s.name,
                parent=new if s.parent == old else s.parent) for s in result.seeds.segments))
    if not is_tree(result):
        return replace(result, seeds=seeds)
    return replace(result, seeds=seeds,
                   branches=tuple(replace(b, seeds=seeds) for b in result.branches),
                   bifurcations=tuple(q.renamed(old, new) for q in result.bifurcations))


def branch_heading(result: Result, shown: int) -> str:
    """The line above a tree's results: which branch the table and chart are of, its
    colour on the images and the model, and how to show another."""
    names = branch_names(result)
    link = result.seeds.segments[branches_of(result)[shown].options.segment]
    where = "" if link.parent is None else f", a branch of {link.parent} at {link.bifurcation}"
    others = ", ".join(f"{n} ({_color_name(k)})"
                       for k, n in enumerate(names) if k != shown)
    return (f"**Branch shown: {names[shown]}** "
            f"({_color_name(shown)}{where}). Choose another "
            f"under **Branch** above (or Segment, in Marks): {others}.")


def draw_result(scene: viser.SceneApi, views: Mapping[str, View], result: Result,
                current: str, by_ffr: bool = False) -> tuple[ModelNodes, int]:
    """Draw a new result in place of the last (a tree branch by branch, else the one
    segment as scene.draw_reconstruction does), the branch of the segment called
    ``current`` shown (the first branch if it was not reconstructed), the model coloured
    by FFR when ``by_ffr`` (:func:`paint_model`). Returns the model's nodes and the index
    of the branch shown; the app fills the results panel."""
    clear_results(scene, views)
    names = branch_names(result)
    shown = names.index(current) if current in names else 0
    if is_tree(result):
        model = draw_tree(scene, views, result, shown, by_ffr)
    else:
        model = draw_reconstruction(scene, views, result)
        if by_ffr:
            paint_model(scene, result, model, shown, by_ffr)
    return model, shown


def marks_key(seeds: Seeds) -> tuple:
    """What of ``seeds`` a result depends on: every complete segment's and landmark's
    clicked points, in order (not their names: a rename changes no figure)."""
    return (tuple((s.a_px, s.b_px, s.parent is not None) for s in seeds.segments),
            tuple((f.a_px, f.b_px) for f in seeds.features))


def draw_out_of_date(scene: viser.SceneApi, views: Mapping[str, View],
                     model: ModelNodes | None, stale: bool) -> None:
    """A line over each image and above the model saying that the traces, MLD and model
    shown are of earlier marks (``stale``), or none."""
    names = [f"{overlay_name(k)}/out_of_date" for k in views] + ["/model/out_of_date"]
    for name in names:
        scene.remove_by_name(name)
    if not stale:
        return
    for v in views.values():  # inside the image's top right corner, clear of its title
        scene.add_label(f"{overlay_name(v.key)}/out_of_date",
                        "⚠ OUT OF DATE: trace and MLD of earlier marks",
                        position=(v.render_w / 2 - 0.01, -v.render_h / 2 + 0.01,
                                  OVERLAY_Z * 2.0), anchor="top-right")
    if model is not None:  # left of the model's box, where the page has room
        at = np.asarray(model.position, float) - [MODEL_SIZE / 2 + 0.02, 0.0, 0.0]
        scene.add_label("/model/out_of_date", "⚠ OUT OF DATE\nthe marks changed after this "
                        "model:\npress Reconstruct", position=(float(at[0]), float(at[1]), 0.0),
                        anchor="center-right")


def _shade(rgb: tuple[int, int, int], fraction: float) -> tuple[int, int, int]:
    """``rgb`` darkened to ``fraction`` of its brightness."""
    return tuple(int(round(c * fraction)) for c in rgb)


def tree_title(tree: TreeReconstruction) -> str:
    """The line over a tree's model coloured by branch."""
    return (f"3D tree, {len(branches_of(tree))} branches, coloured as on the images; drag "
            "to rotate\nthe chart is of the branch chosen under Branch")


def draw_tree(scene: viser.SceneApi, views: Mapping[str, View], tree: TreeReconstruction,
              shown: int, by_ffr: bool = False) -> ModelNodes:
    """Every branch on both images and the tree in 3D (module docstring); branch ``shown``
    highlighted, its MLD and lesion ends marked. Returns the model's nodes."""
    draw_refusal(scene, views, None)
    for v in views.values():  # the one-segment trace and back-projection are not used
        v.nodes.trace.points = np.zeros((0, 2, 3), np.float32)
        v.nodes.backproj.points = np.zeros((0, 2, 3), np.float32)
    draw_flagged(scene, views, tree)
    draw_catheters(scene, views, tree)
    parts = branches_of(tree)
    T, _, centre = model_placement(np.asarray(tree.tree_surface.mesh.vertices),
                                   parts[0].view_a.R_view_from_world, views)
    root = scene.add_frame("/model", show_axes=False)  # the title: paint_model's
    model = ModelNodes(root=root, position=centre, T_scene_from_world=T)
    highlight_branch(scene, views, tree, model, shown, by_ffr)
    return model


@lru_cache(maxsize=1)
def _vertex_branch(tree: TreeReconstruction) -> NDArray[np.int64]:
    """The branch (V,) whose 3D centerline is nearest each vertex of the tree's mesh (the
    last tree's, kept: each switch of the branch shown recolours the same mesh)."""
    from scipy.spatial import cKDTree

    parts = branches_of(tree)
    X_all = np.vstack([b.centerline_3d.X_world for b in parts])
    owner = np.concatenate([np.full(len(b.centerline_3d.X_world), k)
                            for k, b in enumerate(parts)])
    _, nearest = cKDTree(X_all).query(np.asarray(tree.tree_surface.mesh.vertices))
    return owner[nearest]


def mesh_colors(tree: TreeReconstruction, shown: int) -> NDArray[np.uint8]:
    """RGB (V, 3) of the tree mesh's vertices: the colour of the branch whose 3D
    centerline is nearest, faded towards grey (:data:`FADE`) but for branch ``shown``."""
    palette = np.array([branch_color(k) for k in range(len(branches_of(tree)))], float)
    faded = (1.0 - FADE) * palette + FADE * np.array(FADE_TO, float)
    faded[shown] = palette[shown]
    return faded[_vertex_branch(tree)].round().astype(np.uint8)


def highlight_branch(scene: viser.SceneApi, views: Mapping[str, View],
                     tree: TreeReconstruction, model: ModelNodes, shown: int,
                     by_ffr: bool = False) -> None:
    """The tree's mesh (mesh_colors: branch ``shown`` in full colour; or each branch's FFR,
    ``by_ffr``: :func:`paint_model`), each branch's lines
    on both images and in 3D with their names, branch ``shown``'s thicker and its MLD and
    lesion ends marked (scene.draw_lesion_marks)."""
    parts = branches_of(tree)
    names = branch_names(tree)
    T = model.T_scene_from_world
    paint_model(scene, tree, model, shown, by_ffr)
    for k, (part, name) in enumerate(zip(parts, names, strict=True)):
        rgb, thickness_px = branch_color(k), SHOWN_PX if k == shown else THICK_PX
        X_world = np.asarray(part.centerline_3d.X_world, dtype=float)
        for key, cl, geom in (("a", part.centerline_a, part.view_a),
                              ("b", part.centerline_b, part.view_b)):
            v, root = views[key], f"{overlay_name(key)}/branches/b{k}"
            scene.add_line_segments(f"{root}/trace", polyline_segments(v.local_from_px(
                cl.points_px, z=OVERLAY_Z * 0.8)).astype(np.float32), rgb,
                thickness=THIN_PX, thickness_units="screen")
            back_local = v.local_from_px(geom.project(X_world), z=OVERLAY_Z * 1.2)
            scene.add_line_segments(f"{root}/backproj", polyline_segments(back_local).astype(
                np.float32), rgb, thickness=thickness_px, thickness_units="screen")
            offset, anchor = name_place(back_local[-1, :2], name, v.nodes.marks.points)
            scene.add_label(f"{root}/name", name, anchor=anchor, font_screen_scale=0.8,
                            position=(*(back_local[-1, :2] + offset), back_local[-1, 2]))
        X_scene = X_world @ T[:3, :3].T + T[:3, 3]
        scene.add_line_segments(f"/model/branches/b{k}", polyline_segments(X_scene).astype(
            np.float32), _shade(rgb, CENTERLINE_SHADE), thickness=thickness_px,
            thickness_units="screen")
        middle_scene = X_scene[len(X_scene) // 2]  # the ends hold the bifurcations, the MLD
        scene.add_label(f"/model/branch_names/b{k}", name,
                        position=tuple(middle_scene + [0.025, 0.0, 0.0]), anchor="center-left")
    rec = parts[shown]
    draw_lesion_marks(scene, views, rec, model, automatic_marks(rec), rec.measurements.mld_mm)


def has_ffr(result: Result) -> bool:
    """Whether any branch of ``result`` (or the one segment) has its FFR."""
    return any(getattr(b, "ffr", None) is not None for b in branches_of(result))


@lru_cache(maxsize=1)
def _vertex_ffr(result: Result) -> NDArray[np.float64]:
    """The FFR (V,) at each vertex of the result's mesh (model_colours.vertex_ffr; the
    last result's, kept: the model is recoloured at each switch)."""
    mesh = result.tree_surface.mesh if is_tree(result) else result.surface.mesh
    return vertex_ffr(branches_of(result), np.asarray(mesh.vertices))


def ffr_title(result: Result) -> str:
    """The line over a model coloured by FFR: what the colours are, and that the FFR is a
    model estimate for research."""
    what = (f"3D tree, {len(branches_of(result))} branches, each coloured by its FFR"
            if is_tree(result) else
            f"3D model, {result.measurements.segment_length_mm:.1f} mm, coloured by FFR")
    return f"{what} (model estimate, research use); drag to rotate\n{FFR_KEY_TEXT}"


def distal_ffr_text(ffr: object) -> str:
    """The label at a vessel's distal end on the model coloured by FFR (an FFRResult)."""
    ci = ffr.ci95
    return f"distal FFR {ffr.distal:.2f}" + ("" if ci is None else
                                             f" (95 % {ci[0]:.2f}-{ci[1]:.2f})")


def paint_model(scene: viser.SceneApi, result: Result, model: ModelNodes, shown: int,
                by_ffr: bool) -> bool:
    """Colour the model's mesh by FFR (``by_ffr``, when the result has one: each vertex
    the FFR of its nearest centerline point, model_colours) with the distal FFR named at
    each vessel's end, or as drawn first (a segment by diameter, a tree by branch with
    branch ``shown`` in full colour); the title over the model says which. Returns
    whether the model is coloured by FFR."""
    by_ffr = by_ffr and has_ffr(result)
    tree = is_tree(result)
    mesh = (result.tree_surface.mesh if tree else result.surface.mesh).copy()
    if by_ffr:
        rgb, title = ffr_colors(_vertex_ffr(result)), ffr_title(result)
    elif tree:
        rgb, title = mesh_colors(result, shown), tree_title(result)
    else:
        rgb = segment_diameter_colors(result, np.asarray(mesh.vertices))
        title = segment_title(result)
    T = model.T_scene_from_world
    mesh.apply_transform(T)
    mesh.visual.vertex_colors = np.column_stack([rgb, np.full(len(rgb), 255, np.uint8)])
    scene.add_mesh_trimesh("/model/mesh", mesh, cast_shadow=False, receive_shadow=False)
    scene.add_label("/model/title", title, position=title_position(model.position),
                    anchor="top-center")
    scene.remove_by_name("/model/ffr_values")
    parts = branches_of(result)
    texts = [distal_ffr_text(p.ffr) if by_ffr and p.ffr is not None else None for p in parts]
    if any(texts):  # clear of the vessels and the labels on the model, in both views
        places = distal_label_places(parts, T, model.position, shown, texts,
                                     branch_names(result) if tree else None, title)
        for k, (text, place) in enumerate(zip(texts, places, strict=True)):
            if text is not None and place is not None:
                scene.add_label(f"/model/ffr_values/b{k}", text, position=place[0],
                                anchor=place[1])
    return by_ffr
