"""Issue 15's viewer item: a vessel tree in the viewer, without a browser.

The real static phantom pair IM7 (A) / IM8 (B) with its three-branch seeds
(tests/data/im7_im8_tree_seeds.json): Reconstruct reconstructs the whole tree,
each branch is drawn in its own colour on both images and in 3D, the Segment
choice switches the results panel to that branch, the downloads are the
tree's; and "New branch from landmark" links a branch to its parent.
"""

from __future__ import annotations

import io
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

from recon.io import load_seeds
from recon.seeds import Seeds
from recon.tree import TreeReconstruction
from viewer_app import ViewerApp
from viewer_app.model_colours import ffr_colors, vertex_ffr
from viewer_app.plot import ffr_plot, profile_plot
from viewer_app.results import ffr_rows
from viewer_app.scene import lesion_points
from viewer_app.tree_view import SHOWN_PX, THICK_PX, branch_color

DATA = Path(__file__).resolve().parents[1] / "data"
SEEDS = DATA / "im7_im8_tree_seeds.json"


@pytest.fixture()
def tree_app(tmp_path: Path) -> Iterator[ViewerApp]:
    """The viewer on IM7 / IM8 with the three-branch tree's seeds."""
    viewer = ViewerApp(str(DATA / "IM7.dcm"), str(DATA / "IM8.dcm"), str(SEEDS),
                       host="127.0.0.1", port=0, autosave_path=tmp_path / "auto.json",
                       out_dir=tmp_path)
    try:
        yield viewer
    finally:
        viewer.stop()


def _mesh_rgb(app: ViewerApp) -> np.ndarray:
    """The vertex colours (V, 3) of the model's mesh as the server sent it."""
    (mesh,) = trimesh.load(io.BytesIO(_node(app, "/model/mesh").glb_data),
                           file_type="glb").geometry.values()
    return np.asarray(mesh.visual.vertex_colors)[:, :3]


def _node(app: ViewerApp, name: str) -> object:
    handle = app.server.scene.get_handle_by_name(name)
    assert handle is not None, f"no scene node {name}"
    return handle


def test_a_tree_is_reconstructed_drawn_per_branch_and_its_results_follow_the_segment(
        tree_app: ViewerApp, tmp_path: Path) -> None:
    app = tree_app
    names = [s.name for s in load_seeds(SEEDS).segments]
    rec = app.reconstruct()
    assert isinstance(rec, TreeReconstruction), app.notifications[-3:]
    assert [rec.seeds.segments[b.options.segment].name for b in rec.branches] == names
    assert app.notifications[-1][:2] == ("success", "Reconstructed")
    assert "3 branches" in app.notifications[-1][2]
    assert app.state.view_b_calibrated is not None  # the tree's calibration, for the lines

    # Each branch its own colour, on both images and in 3D, its lines where it projects.
    for key in ("a", "b"):  # the one-segment trace and back-projection stay empty
        assert len(app.views[key].nodes.trace.points) == 0
        assert len(app.views[key].nodes.backproj.points) == 0
    colours = []
    for k, branch in enumerate(rec.branches):
        rgb = branch_color(k)
        for key, geom, cl in (("a", branch.view_a, branch.centerline_a),
                              ("b", branch.view_b, branch.centerline_b)):
            v = app.views[key]
            back = _node(app, f"/over_{key}/branches/b{k}/backproj")
            expected = v.local_from_px(geom.project(branch.centerline_3d.X_world))
            np.testing.assert_allclose(back.points[:, 0, :2], expected[:-1, :2], atol=1e-5)
            assert np.all(back.colors.reshape(-1, 3) == rgb)
            trace = _node(app, f"/over_{key}/branches/b{k}/trace")
            assert len(trace.points) == len(cl.points_px) - 1
            assert np.all(trace.colors.reshape(-1, 3) == rgb)
            assert _node(app, f"/over_{key}/branches/b{k}/name").text == names[k]
        line_3d = _node(app, f"/model/branches/b{k}")
        assert len(line_3d.points) == len(branch.centerline_3d.X_world) - 1
        colours.append(rgb)
    assert len(set(colours)) == 3
    glb = _node(app, "/model/mesh").glb_data  # the tree's one mesh, coloured by branch
    scene_mesh = trimesh.load(io.BytesIO(glb), file_type="glb")
    (mesh,) = scene_mesh.geometry.values()
    assert len(mesh.faces) == len(rec.tree_surface.mesh.faces)
    vertex_rgb = {tuple(c) for c in np.asarray(mesh.visual.vertex_colors)[:, :3]}
    assert len(vertex_rgb) == 3 and colours[app.shown_branch] in vertex_rgb

    # The Segment choice switches the table, the chart, the sliders and the highlight.
    bifurcations = app.panels.results.bifurcations.content
    for bq in rec.bifurcations:
        assert bq.name in bifurcations and f"**{bq.medina}**" in bifurcations
        assert f"{bq.bifurcation_angle_deg:.0f}°" in bifurcations
        assert f"{bq.proximal_angle_deg:.0f}°" in bifurcations
        assert f"{bq.side_branch.reference_diameter_mm:.2f} mm" in bifurcations
    for k in (1, 2, 0):
        app.set_segment(names[k])
        branch, m = rec.branches[k], rec.branches[k].measurements
        assert app.branch is branch and app.shown_branch == k
        assert app.panels.results.branch.value == names[k]
        assert f"**Branch shown: {names[k]}**" in app.panels.results.branch_note.content
        clinical = app.panels.results.clinical.content
        assert f"| Minimal lumen diameter | **{m.mld_mm:.2f} mm**" in clinical
        assert f"| % diameter stenosis | **{m.diameter_stenosis_pct:.0f} %**" in clinical
        assert f"| Segment length | {m.segment_length_mm:.1f} mm" in clinical
        assert np.array_equal(app.panels.results.plot.image,
                              profile_plot(branch, width=440, height=440))
        s = branch.profile.s_mm
        assert s[-1] - 0.1 < app.panels.results.lesion_end.max <= s[-1]
        for j in range(3):
            wide = _node(app, f"/over_a/branches/b{j}/backproj").thickness
            assert wide == (SHOWN_PX if j == k else THICK_PX)
        glb = _node(app, "/model/mesh").glb_data  # its part of the mesh in full colour
        (mesh,) = trimesh.load(io.BytesIO(glb), file_type="glb").geometry.values()
        rgb = np.asarray(mesh.visual.vertex_colors)[:, :3]
        assert {tuple(c) for c in rgb} & set(colours) == {branch_color(k)}
        mld_px = branch.view_a.project(lesion_points(branch, {"MLD": m.mld_s_mm})["MLD"][None])
        lesion = _node(app, "/over_a/lesion").points  # the MLD first (float16 in viser)
        np.testing.assert_allclose(lesion[0, :2], app.views["a"].local_from_px(mld_px)[0, :2],
                                   atol=5e-4)
    # Coloured by FFR (issue 47): each branch by its own pullback, its distal value named;
    # the branch shown's chart; back to the branch colours.
    assert all(b.ffr is not None for b in rec.branches), rec.warnings
    assert app.set_ffr_colouring(True)
    V = np.asarray(rec.tree_surface.mesh.vertices)
    rgb = _mesh_rgb(app)
    assert np.array_equal(rgb, ffr_colors(vertex_ffr(rec.branches, V)))
    X_all = np.vstack([b.centerline_3d.X_world for b in rec.branches])
    _, nearest = cKDTree(X_all).query(V)
    ends = np.cumsum([len(b.centerline_3d.X_world) for b in rec.branches]) - 1
    for k, branch in enumerate(rec.branches):  # round each branch's distal end: its value
        end = nearest == ends[k]
        assert end.sum() > 10 and np.all(rgb[end] == ffr_colors([branch.ffr.distal])[0])
        text = _node(app, f"/model/ffr_values/b{k}").text
        assert text.startswith(f"distal FFR {branch.ffr.distal:.2f}")
    app.set_segment(names[1])
    assert np.array_equal(_mesh_rgb(app), rgb)  # a switch of branch keeps the FFR colours
    assert np.array_equal(app.panels.results.ffr_plot.image, ffr_plot(rec.branches[1]))
    assert ffr_rows(rec.branches[1])[0] in app.panels.results.clinical.content
    assert not app.set_ffr_colouring(False)
    assert {tuple(c) for c in _mesh_rgb(app)} & set(colours) == {branch_color(1)}
    app.set_segment(names[2])  # the lesion sliders move that branch's ends
    lesion = app.set_lesion(5.0, 20.0)
    s, d = rec.branches[2].profile.s_mm, rec.branches[2].profile.diameter_smooth_mm
    assert lesion["mld_mm"] == pytest.approx(float(np.min(d[(s >= 5.0) & (s <= 20.0)])))

    # Downloads: the whole tree, as the command line writes it.
    stl = trimesh.load(io.BytesIO(app.export("stl")), file_type="stl")
    assert stl.is_watertight and len(stl.faces) == len(rec.tree_surface.mesh.faces)
    lines = app.export("centerline.csv").decode().splitlines()
    assert lines[0].split(",")[-1] == "branch"
    counts = [len(b.centerline_3d.s_mm) for b in rec.branches]
    branch_ids = np.array([int(line.rsplit(",", 1)[1]) for line in lines[1:]])
    assert np.array_equal(branch_ids, np.repeat(np.arange(3), counts))
    (tmp_path / "c.vtp").write_bytes(app.export("centerline.vtp"))
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(tmp_path / "c.vtp"))
    reader.Update()
    poly = reader.GetOutput()
    assert poly.GetNumberOfLines() == 3
    assert np.array_equal(vtk_to_numpy(poly.GetPointData().GetArray("BranchId")), branch_ids)
    n_notes = len(app.notifications)
    app.download("centerline.vtp")  # through the page's path: no error
    assert not [n for n in app.notifications[n_notes:] if n[0] == "error"]

    # One complete segment again: today's one-segment reconstruction, the tree's nodes gone.
    seeds = load_seeds(SEEDS)
    app.state.load_seeds(Seeds(segments=seeds.segments[:1], features=seeds.features))
    single = app.reconstruct()
    assert single is not None and not isinstance(single, TreeReconstruction)
    assert app.server.scene.get_handle_by_name("/over_a/branches/b1/backproj") is None
    assert len(app.views["a"].nodes.backproj.points) > 10
    assert not app.panels.results.branch.visible and not app.panels.results.bifurcations.visible


def test_new_branch_from_landmark_in_the_app(tree_app: ViewerApp) -> None:
    """The button's command: without a selected landmark a notification says what to click;
    with one the branch is linked, shown in the summary and autosaved; Undo removes it."""
    app = tree_app
    app.select(None)
    assert app.new_branch() is None
    level, title, body = app.notifications[-1]
    assert (level, title) == ("error", "New branch failed")
    assert "select the bifurcation landmark" in body and "\n" not in body
    upper = next(m for m in app.state.marks if m.kind == "feature" and m.view == "b"
                 and app.state.feature_name(m.group) == "arc/upper")
    app.set_segment("long arc")
    app.select(upper.id)
    index = app.new_branch()
    assert index == 3 and app.state.segment_names[3] == "Segment 4"
    assert app.state.segment_links["Segment 4"] == ("long arc", "arc/upper")
    assert app.panels.marks.segment.value == "Segment 4"
    assert "Segment 4** (current) ↳ branch of long arc at landmark arc/upper" in \
        app.panels.marks.summary.content
    assert '"Segment 4": [' in Path(app.autosave.path).read_text()
    assert app.undo()
    assert app.state.segment_names == [s.name for s in load_seeds(SEEDS).segments]
    assert "Segment 4" not in app.state.segment_links


def test_a_branch_name_goes_where_no_mark_or_its_label_lies() -> None:
    """Beside a distal end with only its own mark, the name goes above right; with a
    landmark and its label there (as "long arc" over D1 / F2 in IM8), to a clear side."""
    from viewer_app.placing import NAME_PLACES, name_place

    end = np.array([0.2, 0.1])
    alone = np.array([[0.2, 0.1, 0.0]])  # the branch's own distal mark
    offset, anchor = name_place(end, "long arc", alone)
    assert anchor == NAME_PLACES[0][1] and np.allclose(offset, NAME_PLACES[0][0])
    crowded = np.vstack([alone, [[0.23, 0.08, 0.0], [0.26, 0.07, 0.0]]])  # up and right
    offset, anchor = name_place(end, "long arc", crowded)
    assert anchor != NAME_PLACES[0][1]
    assert offset[0] < 0  # the text runs to the left, away from the landmarks


def test_a_segment_renamed_after_reconstruct_is_renamed_in_the_results(
        tree_app: ViewerApp) -> None:
    """Renaming a reconstructed segment renames its branch in the results shown (the Branch
    choice, the line above the table, the bifurcation table, the names on the images and
    report.json), without a new Reconstruct; undoing the rename undoes it there too."""
    app = tree_app
    names = [s.name for s in load_seeds(SEEDS).segments]
    assert app.reconstruct() is not None, app.notifications[-3:]
    app.set_segment(names[1])
    assert app.rename_segment("D1") == "D1"
    results = app.panels.results
    assert tuple(results.branch.options) == (names[0], "D1", names[2])
    assert results.branch.value == "D1" and app.shown_branch == 1
    assert "**Branch shown: D1**" in results.branch_note.content
    parent = load_seeds(SEEDS).segments[1].parent
    assert f"{parent} › D1" in results.bifurcations.content
    assert names[1] not in results.bifurcations.content
    for key in ("a", "b"):
        assert _node(app, f"/over_{key}/branches/b1/name").text == "D1"
    report = json.loads(app.export("report.json"))
    assert [b["inputs"]["segment"] for b in report["branches"]] == [names[0], "D1", names[2]]
    assert [b["parent"] for b in report["branches"]][1] == parent
    app.set_segment(names[2])  # the renamed branch is chosen by its new name
    app.set_segment("D1")
    assert app.shown_branch == 1 and app.state.segment_names[1] == "D1"
    assert app.undo()
    assert tuple(results.branch.options) == tuple(names)
    assert _node(app, "/over_a/branches/b1/name").text == names[1]
    app.set_segment(names[0])  # the parent renamed: its branches' links follow
    assert app.rename_segment("LAD") == "LAD"
    assert f"LAD › {names[1]}" in results.bifurcations.content
    report = json.loads(app.export("report.json"))
    assert [b["parent"] for b in report["branches"]] == [None, "LAD", "LAD"]


def test_the_labels_of_marks_a_few_pixels_apart_do_not_cover_each_other() -> None:
    """Two waypoints 5 px apart (about 0.01 scene units) once drew their labels "1w1" and
    "1w2" over each other: the second label goes where it clears the first; a mark far
    away keeps the first place; three marks on one spot use all three places."""
    from viewer_app.placing import LABEL_PLACES, MARK_LABEL_WIDTH, label_box, label_places

    pts = np.array([[0.0, 0.0, 0.0], [0.01, 0.004, 0.0], [0.4, 0.3, 0.0],
                    [0.4, 0.3, 0.0], [0.4, 0.3, 0.0]])
    places = label_places(pts)
    boxes = [label_box(p[:2] + off[:2], anchor, MARK_LABEL_WIDTH)
             for p, (off, anchor) in zip(pts, places, strict=True)]

    def overlap(a, b) -> bool:
        return a[1] > b[0] and b[1] > a[0] and a[3] > b[2] and b[3] > a[2]

    assert places[0][1] == LABEL_PLACES[0][1] and places[2][1] == LABEL_PLACES[0][1]
    assert not overlap(boxes[0], boxes[1])
    assert [a for _, a in places[2:]] == [a for _, a in LABEL_PLACES]
    assert not any(overlap(boxes[i], boxes[j]) for i in (2, 3, 4) for j in (2, 3, 4) if i < j)


def test_every_lesion_s_mld_is_marked() -> None:
    """Issue 46 item 5: besides the MLD (and its lesion's ends), every other lesion's MLD
    is marked on the images and the model, named L2, L3, ... by its number."""
    from types import SimpleNamespace

    from viewer_app.scene import automatic_marks

    def lesion(number: int, s_mm: float) -> SimpleNamespace:
        return SimpleNamespace(number=number, narrowing=SimpleNamespace(mld_s_mm=s_mm))

    m = SimpleNamespace(mld_s_mm=48.0, has_lesion=True, lesion_start_s_mm=44.0,
                        lesion_end_s_mm=52.0)
    rec = SimpleNamespace(measurements=m, lesions=SimpleNamespace(
        lesions=(lesion(1, 20.0), lesion(2, 48.0), lesion(3, 70.0)), primary=1))
    assert automatic_marks(rec) == {"MLD": 48.0, "lesion start": 44.0, "lesion end": 52.0,
                                    "L1": 20.0, "L3": 70.0}
    assert automatic_marks(SimpleNamespace(measurements=m)) == {
        "MLD": 48.0, "lesion start": 44.0, "lesion end": 52.0}
