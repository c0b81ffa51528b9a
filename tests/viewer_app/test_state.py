"""viewer_app.state without viser or images: marks, modes, undo, seeds, epipolar lines, autosave."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from recon.geometry import ViewGeometry, epipolar_lines
from recon.seeds import Feature, Seeds, Segment, seeds_from_dict
from viewer_app.autosave import Autosave
from viewer_app.state import MarkState, clip_line_to_image

VIEW_A = ViewGeometry(-30.0, 20.0, 1000.0, 750.0, (0.3, 0.3), 400, 500)
VIEW_B = ViewGeometry(35.0, 15.0, 1000.0, 750.0, (0.3, 0.3), 400, 500)


def _line_distance_px(seg: np.ndarray, point_px: np.ndarray) -> float:
    """Distance of a point (2,) to the infinite line through a segment (2, 2)."""
    d = seg[1] - seg[0]
    w = point_px - seg[0]
    return float(abs(d[0] * w[1] - d[1] * w[0]) / np.linalg.norm(d))


def _state() -> MarkState:
    return MarkState(VIEW_A, VIEW_B)


def test_clip_line_to_image_known_cases() -> None:
    # Horizontal line row = 100 across a 500 x 400 image.
    seg = clip_line_to_image([0.0, 1.0, -100.0], 500, 400)
    np.testing.assert_allclose(sorted(seg[:, 0]), [-0.5, 499.5])
    np.testing.assert_allclose(seg[:, 1], [100.0, 100.0])
    # Diagonal col = row through the corner region.
    seg = clip_line_to_image(np.array([1.0, -1.0, 0.0]) / np.sqrt(2), 500, 400)
    np.testing.assert_allclose(seg[np.argsort(seg[:, 0])], [[-0.5, -0.5], [399.5, 399.5]])
    # A line outside the image.
    assert clip_line_to_image([0.0, 1.0, 1000.0], 500, 400) is None


def test_modes_build_segments_and_feature_pairs() -> None:
    st = _state()
    st.set_mode("proximal")
    st.click("a", 10, 20)
    st.click("b", 11, 21)
    st.set_mode("waypoint")
    st.click("a", 30, 40)
    st.click("a", 50, 60)
    st.set_mode("distal")
    st.click("a", 100, 120)
    assert st.mode == "guided"  # an end mode is one click (a redo), then guided again
    st.set_mode("distal")
    st.click("a", 101, 121)  # replaces the distal end in A
    st.click("b", 90, 95)  # guided: B has its proximal end, so this is its distal end
    st.set_mode("feature")
    st.click("a", 200, 210)  # landmark in A ...
    st.click("b", 220, 230)  # ... then its partner in B
    st.click("b", 300, 310)  # a second landmark, B first
    seeds = st.to_seeds()
    assert seeds.segments == (
        Segment("Segment 1", ((10, 20), (30, 40), (50, 60), (101, 121)), ((11, 21), (90, 95))),
    )
    assert seeds.features == (Feature("feature 1", (200, 210), (220, 230)),)
    assert st.missing() == ["feature 2: partner missing in A"]
    st.click("a", 305, 315)
    assert len(st.to_seeds().features) == 2
    labels = {st.label(m) for m in st.marks}
    assert {"1p", "1d", "1w1", "1w2", "F1", "F2"} <= labels


@pytest.mark.parametrize("order", ["aabb", "bbaa", "abab", "baba", "abba"])
def test_guided_clicks_place_ends_then_landmarks_in_any_order(order: str) -> None:
    st = _state()
    assert st.mode == "guided"
    pts = {"a": [(10, 20), (100, 120), (200, 210)], "b": [(11, 21), (90, 95), (220, 230)]}
    used = {"a": 0, "b": 0}
    for view in order + "ab":  # both ends in each view, then one landmark pair
        st.click(view, *pts[view][used[view]])
        used[view] += 1
        assert st.mode == "guided"
    seeds = st.to_seeds()
    assert seeds.segments == (Segment("Segment 1", ((10, 20), (100, 120)), ((11, 21), (90, 95))),)
    assert seeds.features == (Feature("feature 1", (200, 210), (220, 230)),)
    assert st.missing() == []


def test_guided_epipolar_line_guides_the_next_click_in_the_other_view() -> None:
    st = _state()
    X = np.array([[5.0, -10.0, 20.0], [-20.0, 15.0, -10.0]])
    pa, pb = VIEW_A.project(X), VIEW_B.project(X)
    st.click("a", *pa[0])  # proximal A
    st.click("a", *pa[1])  # distal A: the next click in B is its proximal end ...
    view, seg = st.epipolar_segment()
    d = seg[1] - seg[0]
    w = pb[0] - seg[0]
    assert view == "b"  # ... so the line drawn in B is the proximal end's
    assert abs(d[0] * w[1] - d[1] * w[0]) / np.linalg.norm(d) < 1e-6
    assert "proximal end" in st.guide_text()


def test_undo_and_clear() -> None:
    st = _state()
    st.click("a", 10, 20)
    st.set_mode("proximal")
    st.click("a", 15, 25)  # replaces the proximal end
    assert [m.point_px for m in st.marks] == [(15.0, 25.0)]
    assert st.undo()
    assert [m.point_px for m in st.marks] == [(10.0, 20.0)]
    st.clear()
    assert st.marks == []
    assert st.undo()
    assert len(st.marks) == 1
    assert st.undo() and st.marks == []
    assert not st.undo()


def test_click_outside_the_image_is_refused_with_a_message() -> None:
    st = _state()
    with pytest.raises(ValueError, match="outside image A"):
        st.click("a", 600.0, 10.0)
    assert st.marks == []


def test_snapper_is_used_and_its_message_kept() -> None:
    def snapper(view, raw):
        if raw[0] < 100:
            return raw + [1.0, 0.0], 1.0, None
        return raw, None, "far from any vessel"

    st = MarkState(VIEW_A, VIEW_B, snapper=snapper)
    m = st.click("a", 50, 50)
    assert m.point_px == (51.0, 50.0) and m.raw_px == (50.0, 50.0) and m.snap_distance_px == 1.0
    m = st.click("b", 150, 50)
    assert m.point_px == (150.0, 50.0) and m.snap_distance_px is None
    assert st.last_message == "far from any vessel"


def test_epipolar_segment_of_the_selected_mark_lies_on_its_line() -> None:
    st = _state()
    X = np.array([[5.0, -10.0, 20.0]])
    pa, pb = VIEW_A.project(X)[0], VIEW_B.project(X)[0]
    st.click("a", *pa)
    view, seg = st.epipolar_segment()
    assert view == "b"
    line = epipolar_lines(pa[None], VIEW_A, VIEW_B)[0]
    np.testing.assert_allclose(seg @ line[:2] + line[2], 0.0, atol=1e-9)
    # the true partner lies on it: distance from pb to the segment's line
    assert _line_distance_px(seg, pb) < 1e-6
    st.click("b", *pb)  # selecting a B mark draws its line in A
    assert st.epipolar_segment()[0] == "a"


def test_calibrated_geometry_is_used_for_epipolar_lines() -> None:
    st = _state()
    truth_b = VIEW_B.with_correction([0.0, 0.02, 0.0], [2.0, 0.0, -1.0])
    X = np.array([[5.0, -10.0, 20.0]])
    pa, pb_true = VIEW_A.project(X)[0], truth_b.project(X)[0]
    st.click("a", *pa)

    def dist() -> float:
        return _line_distance_px(st.epipolar_segment()[1], pb_true)

    assert dist() > 3.0
    st.set_calibrated_b(truth_b)
    assert dist() < 1e-6


def test_seeds_round_trip_through_marks() -> None:
    seeds = seeds_from_dict(
        {
            "segments": [
                {"name": "LAD", "a": [[1, 2], [3, 4], [5, 6]], "b": [[7, 8], [9, 10]]},
                {"name": "LCx", "a": [[11, 12], [13, 14]], "b": [[15, 16], [17, 18]]},
            ],
            "features": [{"name": "feature 1", "a": [20, 21], "b": [22, 23]}],
        }
    )
    st = _state()
    st.load_seeds(seeds)
    assert st.to_seeds() == seeds
    assert st.segment_names == ["LAD", "LCx"]


TREE = {  # docs/seeds-format.md's version-2 example
    "version": 2,
    "segments": [
        {"name": "LAD", "a": [[170.5, 54.1], [179.9, 139.1], [323.0, 261.2]],
         "b": [[368.6, 101.1], [371.2, 177.0], [401.9, 331.4]]},
        {"name": "D1", "parent": "LAD", "bifurcation": "LAD/D1",
         "a": [[192.1, 160.3], [240.7, 181.0]], "b": [[379.0, 196.7], [420.2, 230.5]]},
    ],
    "features": [{"name": "LAD/D1", "a": [192.1, 160.3], "b": [379.0, 196.7]}],
}


def test_a_tree_keeps_its_branches_through_load_save_and_autosave(tmp_path: Path) -> None:
    """Issue 15: the viewer wrote a tree's branch as a root (parent and bifurcation lost)."""
    seeds = seeds_from_dict(TREE)
    st = _state()
    st.load_seeds(seeds)
    saved = st.to_seeds()
    assert saved == seeds
    assert [(s.parent, s.bifurcation) for s in saved.segments] == [(None, None),
                                                                   ("LAD", "LAD/D1")]
    assert saved.to_dict()["version"] == 2
    store = Autosave(tmp_path / "auto.json", str(tmp_path / "a.dcm"), str(tmp_path / "b.dcm"))
    store.save(st)
    assert seeds_from_dict(json.loads(store.path.read_text())) == seeds
    restored = _state()
    assert store.load_into(restored, None)
    assert restored.to_seeds() == seeds
    # Marks added after the restart keep the tree; an incomplete parent leaves the branch a
    # root in the seeds (a valid file) but the link waits in the state for the parent.
    restored.set_mode("waypoint")
    restored.click("a", 200.0, 170.0)
    assert restored.to_seeds().segments[1].parent == "LAD"
    restored.marks = [m for m in restored.marks if not (m.group == 0 and m.kind == "distal")]
    assert [s.name for s in restored.to_seeds().segments] == ["D1"]
    assert restored.to_seeds().segments[0].parent is None
    assert restored.to_dict()["viewer"]["segment_links"] == {"D1": ["LAD", "LAD/D1"]}
    restored.clear()
    assert restored.to_dict()["viewer"]["segment_links"] == {}
    assert restored.undo()
    assert restored.to_dict()["viewer"]["segment_links"] == {"D1": ["LAD", "LAD/D1"]}


def test_autosave_round_trip_keeps_incomplete_marks(tmp_path: Path) -> None:
    a, b = tmp_path / "a.dcm", tmp_path / "b.dcm"
    st = _state()
    st.click("a", 10, 20)
    st.set_mode("feature")
    st.click("b", 30, 40)  # a feature still waiting for its partner
    store = Autosave(tmp_path / "auto.json", str(a), str(b))
    store.save(st)
    doc = json.loads((tmp_path / "auto.json").read_text())
    seeds_from_dict(doc)  # the autosave is a valid seeds document as well
    restored = _state()
    assert store.load_into(restored, None)
    assert [(m.kind, m.view, m.point_px) for m in restored.marks] == [
        ("proximal", "a", (10.0, 20.0)),
        ("feature", "b", (30.0, 40.0)),
    ]
    assert restored.mode == "feature"
    # a seeds file older than the autosave does not hide it
    seeds_path = tmp_path / "seeds.json"
    seeds_path.write_text(json.dumps(Seeds().to_dict()))
    t = (tmp_path / "auto.json").stat().st_mtime
    os.utime(seeds_path, (t - 10, t - 10))
    assert store.load_into(_state(), seeds_path) and store.notice is None
    # a seeds file newer than the autosave wins, and the autosave is kept aside, not lost
    kept = (tmp_path / "auto.json").read_bytes()
    os.utime(seeds_path, (t + 10, t + 10))
    assert not store.load_into(_state(), seeds_path)
    assert store.kept_aside is not None and store.kept_aside.read_bytes() == kept
    assert store.kept_aside.name.startswith("auto.older-") and not (tmp_path / "auto.json").exists()
    assert "older than the seeds file" in store.notice and str(store.kept_aside) in store.notice


def _saved(tmp_path: Path) -> tuple[Autosave, MarkState]:
    st = _state()
    st.load_seeds(Seeds(
        segments=(Segment("LAD mid", ((1.0, 2.0), (3.0, 4.0)), ((5.0, 6.0), (7.0, 8.0))),),
        features=(Feature("D1 bifurcation", (10.0, 11.0), (12.0, 13.0)),
                  Feature("septal", (20.0, 21.0), (22.0, 23.0))),
    ))
    store = Autosave(tmp_path / "auto.json", str(tmp_path / "a.dcm"), str(tmp_path / "b.dcm"))
    store.save(st)
    return store, st


def test_feature_and_segment_names_survive_the_autosave(tmp_path: Path) -> None:
    store, st = _saved(tmp_path)
    doc = json.loads(store.path.read_text())
    assert doc["autosave_version"] == 2 and doc["saved_at"].endswith("Z")
    restored = _state()
    assert store.load_into(restored, None)
    assert restored.to_seeds() == st.to_seeds()
    assert [f.name for f in restored.to_seeds().features] == ["D1 bifurcation", "septal"]


@pytest.mark.parametrize("damage", ["invalid UTF-8", "deep nesting", "not JSON", "a list",
                                    "marks not a list", "a folder", "newer version",
                                    "another pair"])
def test_an_autosave_that_cannot_be_restored_is_kept_aside_never_overwritten(
    tmp_path: Path, damage: str
) -> None:
    store, _ = _saved(tmp_path)
    doc = json.loads(store.path.read_text())
    data: bytes | None = None
    if damage == "invalid UTF-8":
        data = store.path.read_bytes().replace(b"LAD", b"L\xffD")
    elif damage == "deep nesting":
        data = b'{"viewer": ' + b"[" * 5000 + b"]" * 5000 + b"}"
    elif damage == "not JSON":
        data = store.path.read_bytes()[:-40]
    elif damage == "a list":
        data = b"[1, 2]"
    elif damage == "marks not a list":
        doc["viewer"]["marks"] = 7
    elif damage == "newer version":
        doc["autosave_version"] = 99
    elif damage == "another pair":
        doc["pair"] = ["/x/a.dcm", "/x/b.dcm"]
    if damage == "a folder":
        store.path.unlink()
        store.path.mkdir()
        (store.path / "inside").write_text("x")
        original = None
    else:
        original = data if data is not None else json.dumps(doc).encode()
        store.path.write_bytes(original)
    restored = _state()
    assert store.load_into(restored, None) is False  # nothing raised
    assert restored.marks == []
    assert store.kept_aside is not None and store.kept_aside.exists()
    if original is not None:
        assert store.kept_aside.read_bytes() == original
    assert store.notice and "\n" not in store.notice and str(store.kept_aside) in store.notice
    store.save(restored)  # the next autosave does not touch the one kept aside
    if original is not None:
        assert store.kept_aside.read_bytes() == original


def test_one_damaged_mark_costs_only_that_mark(tmp_path: Path) -> None:
    store, st = _saved(tmp_path)
    doc = json.loads(store.path.read_text())
    doc["viewer"]["marks"][1]["point_px"] = ["x", None]
    doc["viewer"]["marks"][2] = "garbage"
    store.path.write_text(json.dumps(doc))
    original = store.path.read_bytes()
    restored = _state()
    assert store.load_into(restored, None)
    assert len(restored.marks) == len(st.marks) - 2
    assert "2 damaged mark(s)" in store.notice
    assert store.kept_aside is not None and store.kept_aside.read_bytes() == original


def test_a_branch_starts_at_the_selected_landmark_undoably_and_survives_the_autosave(
        tmp_path: Path) -> None:
    """Issue 15, the viewer's "New branch from landmark": the current segment is the parent,
    the selected landmark (placed in both views) the bifurcation, the branch's proximal ends
    sit on it; without such a landmark the clinician is told what to click."""
    from viewer_app.results import marks_markdown

    st = _state()
    for view, col, row in (("a", 10, 20), ("a", 100, 120), ("b", 11, 21), ("b", 90, 95)):
        st.click(view, col, row)  # guided: the main vessel's ends
    st.select(None)
    with pytest.raises(ValueError, match="select the bifurcation landmark"):
        st.new_branch()
    st.select(st.marks[0].id)  # a segment end is no landmark
    with pytest.raises(ValueError, match="select the bifurcation landmark"):
        st.new_branch()
    landmark_a = st.click("a", 60, 70)  # guided: a landmark, its partner not yet in B
    with pytest.raises(ValueError, match="only in A; click the bifurcation in B"):
        st.new_branch()
    assert st.segment_names == ["Segment 1"] and st.segment_links == {}
    st.click("b", 50, 55)  # the partner: the landmark is complete and selected
    n_marks = len(st.marks)

    assert st.new_branch() == 1
    assert st.segment_names == ["Segment 1", "Segment 2"] and st.current_segment == 1
    assert st.segment_links == {"Segment 2": ("Segment 1", "feature 1")}
    starts = {m.view: m.point_px for m in st.marks if m.group == 1 and m.kind == "proximal"}
    assert starts == {"a": landmark_a.point_px, "b": (50.0, 55.0)}
    assert st.next_clicks() == {"a": "distal end", "b": "distal end"}
    summary = marks_markdown(st, float("nan"), tmp_path / "auto.json")
    assert "**Segment 2** (current) ↳ branch of Segment 1 at landmark feature 1" in summary
    st.click("a", 20, 160)
    st.click("b", 30, 150)
    seeds = st.to_seeds()
    assert [(s.name, s.parent, s.bifurcation) for s in seeds.segments] == [
        ("Segment 1", None, None), ("Segment 2", "Segment 1", "feature 1")]
    assert seeds.segments[1].a_px == ((60.0, 70.0), (20.0, 160.0))
    assert seeds_from_dict(seeds.to_dict()) == seeds  # a valid version-2 seeds file

    store = Autosave(tmp_path / "auto.json", str(tmp_path / "a.dcm"), str(tmp_path / "b.dcm"))
    store.save(st)
    restored = _state()
    assert store.load_into(restored, None)
    assert restored.to_seeds() == seeds
    assert restored.segment_links == st.segment_links
    reloaded = _state()
    reloaded.load_seeds(seeds_from_dict(seeds.to_dict()))
    assert reloaded.segment_links == st.segment_links

    # Undo: the two distal ends, then the branch in one step (its link and ends gone).
    assert st.undo() and st.undo()
    assert st.undo()
    assert st.segment_names == ["Segment 1"] and st.segment_links == {}
    assert len(st.marks) == n_marks and st.current_segment == 0
    # A second segment's default name never repeats one the seeds brought.
    named = _state()
    named.load_seeds(seeds_from_dict({"segments": [
        {"name": "Segment 2", "a": [[1, 2], [3, 4]], "b": [[5, 6], [7, 8]]}]}))
    assert named.segment_names[named.new_segment()] == "Segment 3"


def test_renaming_a_segment_carries_its_branch_links_undoably_into_the_seeds(
        tmp_path: Path) -> None:
    """A clinician names the vessels (LAD, D1): the current segment is renamed, the link of
    its branch and its own link follow, one undo step brings the old names back, and an
    empty, over-long or taken name is refused with a message saying so."""
    st = _state()
    for view, col, row in (("a", 10, 20), ("a", 100, 120), ("b", 11, 21), ("b", 90, 95)):
        st.click(view, col, row)
    st.click("a", 60, 70)
    st.click("b", 50, 55)  # a landmark in both views, selected
    st.new_branch()
    st.click("a", 20, 160)
    st.click("b", 30, 150)
    st.set_current_segment(0)
    assert st.rename_segment("  LAD \n") == "LAD"  # spaces and a line break collapsed
    st.set_current_segment(1)
    assert st.rename_segment("D1") == "D1"
    assert st.segment_names == ["LAD", "D1"]
    assert st.segment_links == {"D1": ("LAD", "feature 1")}
    seeds = st.to_seeds()
    assert [(s.name, s.parent) for s in seeds.segments] == [("LAD", None), ("D1", "LAD")]
    assert seeds_from_dict(seeds.to_dict()) == seeds
    for bad, said in (("   ", "type a name"), ("x" * 81, "1 to 80 characters"),
                      ("LAD", "already called 'LAD'")):
        with pytest.raises(ValueError, match=said):
            st.rename_segment(bad)
    assert st.segment_names == ["LAD", "D1"]
    assert st.rename_segment("D1") == "D1" and st.undo()  # the same name: no undo step
    assert st.segment_names == ["LAD", "Segment 2"]
    assert st.segment_links == {"Segment 2": ("LAD", "feature 1")}
    store = Autosave(tmp_path / "auto.json", str(tmp_path / "a.dcm"), str(tmp_path / "b.dcm"))
    store.save(st)
    restored = _state()
    assert store.load_into(restored, None)
    assert restored.segment_names == ["LAD", "Segment 2"]
    assert restored.segment_links == st.segment_links


def _ends(st: MarkState) -> None:
    """Both ends of segment 1 in both views (guided), so that the next clicks are
    landmarks."""
    for view, pts in (("a", [(10, 20), (100, 120)]), ("b", [(11, 21), (90, 95)])):
        for p in pts:
            st.click(view, *p)


@pytest.mark.parametrize("order", ["aabb", "bbaa", "abab", "baab", "abba"])
def test_landmarks_clicked_view_by_view_pair_in_click_order(order: str) -> None:
    """Issue 46 item 1: two landmarks clicked in one view, then their partners in the
    other, pair first with first (the second click in A replaced the first, which still
    waited, and the B clicks were paired with the wrong points)."""
    X = np.array([[5.0, -10.0, 20.0], [-20.0, 15.0, -10.0]])
    px = {"a": VIEW_A.project(X), "b": VIEW_B.project(X)}
    st = _state()
    _ends(st)
    used = {"a": 0, "b": 0}
    for view in order:
        st.click(view, *px[view][used[view]])
        used[view] += 1
    feats = st.to_seeds().features
    assert len(feats) == 2 and st.missing() == []
    for f, k in zip(feats, (0, 1), strict=True):
        np.testing.assert_allclose(f.a_px, px["a"][k])
        np.testing.assert_allclose(f.b_px, px["b"][k])
    assert all(st.pairing_doubt(m) is None for m in st.marks)


def test_the_guide_names_the_landmarks_waiting_and_which_pairs_next() -> None:
    st = _state()
    _ends(st)
    st.click("a", 200, 210)
    st.click("a", 300, 310)
    text = st.guide_text()
    assert "Landmarks F1, F2 wait for their partners in B" in text
    assert "pairs with F1" in text
    assert st.waiting_landmarks("a") == [0, 1]
    # the magenta line drawn in B is F1's, the landmark the next B click pairs with
    line = epipolar_lines(np.array([[200.0, 210.0]]), VIEW_A, VIEW_B)[0]
    view, seg = st.epipolar_segment()
    assert view == "b"
    for p in seg:
        assert abs(line @ [*p, 1.0]) / np.hypot(*line[:2]) < 1e-6


def test_a_landmark_clicked_again_on_its_place_is_not_a_second_pair() -> None:
    st = _state()
    _ends(st)
    st.click("a", 200, 210)
    st.click("b", 220, 230)
    st.click("a", 202, 211)  # the same branch point, clicked again in A
    st.click("b", 221, 232)  # ... and in B
    feats = st.to_seeds().features
    assert feats == (Feature("feature 1", (202, 211), (221, 232)),)


def test_a_landmark_paired_out_of_order_is_doubted() -> None:
    """Two landmarks in A, then F2's partner clicked first in B: it pairs with F1 (click
    order), and the state says it lies on F2's line instead."""
    X = np.array([[5.0, -10.0, 20.0], [-20.0, 15.0, -10.0]])
    pa, pb = VIEW_A.project(X), VIEW_B.project(X)
    st = _state()
    _ends(st)
    st.click("a", *pa[0])
    st.click("a", *pa[1])
    mark = st.click("b", *pb[1])  # F2's partner, paired with F1
    assert st.partner(mark).point_px == pytest.approx(tuple(pa[0]))
    doubt = st.pairing_doubt(mark)
    assert doubt is not None and "F2's" in doubt and "Undo" in doubt


def test_a_mark_moved_and_deleted_with_undo() -> None:
    st = _state()
    _ends(st)
    distal = next(m for m in st.marks if m.kind == "distal" and m.view == "a")
    moved = st.move_mark(distal.id, 150.0, 160.0)
    assert (moved.id, moved.kind, moved.group) == (distal.id, "distal", 0)
    assert moved.point_px == (150.0, 160.0) and st.selected_id == distal.id
    assert st.to_seeds().segments[0].a_px[-1] == (150.0, 160.0)
    # a drag: the first move is the undo step, the later ones are not
    st.move_mark(distal.id, 151.0, 161.0)
    st.move_mark(distal.id, 152.0, 162.0, snap=False, undoable=False)
    assert st.undo() and st.mark_by_id(distal.id).point_px == (150.0, 160.0)
    assert st.undo() and st.mark_by_id(distal.id).point_px == distal.point_px
    st.select(distal.id)
    gone = st.delete_mark()
    assert gone.id == distal.id and st.mark_by_id(distal.id) is None
    assert st.selected_id is None and "Segment 1: distal end missing in A" in st.missing()
    assert st.undo() and st.mark_by_id(distal.id) == distal
    st.select(None)
    with pytest.raises(ValueError, match="select a mark first"):
        st.delete_mark()
    with pytest.raises(ValueError, match="no mark with id 999"):
        st.move_mark(999, 1.0, 1.0)


def test_a_click_s_message_goes_with_the_marks_it_was_about() -> None:
    """The "not snapped" line of a click stayed in the marks panel after Clear marks,
    an Undo or loaded seeds (issue 46 item 2)."""
    def snapper(view: str, raw: np.ndarray) -> tuple[np.ndarray, None, str]:
        return raw, None, "not snapped, kept where clicked"

    st = MarkState(VIEW_A, VIEW_B, snapper=snapper)
    for change in (st.clear, st.undo, lambda: st.load_seeds(Seeds(segments=(), features=())),
                   st.delete_mark):
        mark = st.click("a", 10.0, 20.0)
        assert st.last_message == "not snapped, kept where clicked"
        st.select(mark.id)
        change()
        assert st.last_message is None
