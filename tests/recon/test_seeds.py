"""recon.seeds: the dataclasses and their dict form (no files)."""

import numpy as np
import pytest
from support import EXAMPLE_SEEDS

from recon.seeds import Feature, Seeds, SeedsError, Segment, seeds_from_dict


def test_objects_build_the_same_dict():
    seeds = Seeds(
        segments=(Segment("s", ((1.0, 2.0), (3.0, 4.0)), ((5.0, 6.0), (7.0, 8.0))),),
        features=(Feature("f", (1.0, 1.0), (2.0, 2.0)),),
    )
    d = seeds.to_dict()
    assert d["segments"][0]["a"] == [[1.0, 2.0], [3.0, 4.0]]
    assert d["features"][0]["b"] == [2.0, 2.0]


def test_the_documented_example_parses_and_round_trips():
    seeds = seeds_from_dict(EXAMPLE_SEEDS, source="example")
    assert seeds.segments[0].name == "LAD mid"
    assert seeds.segments[0].a.shape == (3, 2)
    pa, pb, names = seeds.correspondences()
    # Segment ends then features; waypoints do not correspond.
    assert np.allclose(pa, [[170.5, 54.1], [323.0, 261.2], [192.1, 160.3]])
    assert np.allclose(pb, [[368.6, 101.1], [401.9, 331.4], [379.0, 196.7]])
    assert names == ["LAD mid proximal", "LAD mid distal", "D1 bifurcation"]
    assert seeds_from_dict(seeds.to_dict()) == seeds


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ([1, 2], "top level"),
        ({"version": 3}, "unsupported version"),
        ({"segments": [{"a": [[1, 2]], "b": [[1, 2], [3, 4]]}]}, "at least two points"),
        ({"segments": [{"a": [[1, "x"], [3, 4]], "b": [[1, 2], [3, 4]]}]}, "segments[0].a[0]"),
        ({"features": [{"a": [1, 2]}]}, "features[0]"),
        ({"features": [{"a": [1, 2], "b": [float("nan"), 1]}]}, "features[0].b"),
    ],
)
def test_bad_documents_name_the_source_and_the_entry(data, message):
    with pytest.raises(SeedsError) as info:
        seeds_from_dict(data, source="marks.json")
    assert str(info.value).startswith("marks.json: ")
    assert message in str(info.value)
    assert "\n" not in str(info.value)


TREE = {
    "version": 2,
    "segments": [
        {"name": "LAD", "a": [[10, 10], [50, 60], [90, 120]], "b": [[20, 15], [80, 130]]},
        {"name": "D1", "parent": "LAD", "bifurcation": "LAD/D1",
         "a": [[50, 60], [80, 50]], "b": [[48, 70], [70, 60]]},
        {"name": "D1 distal", "parent": "D1", "bifurcation": "D1 split",
         "a": [[80, 50], [100, 40]], "b": [[70, 60], [90, 50]]},
    ],
    "features": [{"name": "LAD/D1", "a": [50, 60], "b": [48, 70]},
                 {"name": "D1 split", "a": [80, 50], "b": [70, 60]}],
}


def test_a_tree_reads_with_its_links_and_round_trips_as_version_2():
    seeds = seeds_from_dict(TREE, source="tree.json")
    assert seeds.is_tree
    assert [s.parent for s in seeds.segments] == [None, "LAD", "D1"]
    assert seeds.segments[1].bifurcation == "LAD/D1"
    assert seeds.segment_index("D1 distal") == 2
    assert seeds.feature("D1 split").b_px == (70.0, 60.0)
    d = seeds.to_dict()
    assert d["version"] == 2 and d["segments"][2]["parent"] == "D1"
    assert seeds_from_dict(d) == seeds


def test_a_tree_free_seeds_is_still_written_as_version_1():
    seeds = seeds_from_dict(EXAMPLE_SEEDS)
    assert not seeds.is_tree
    assert seeds.to_dict()["version"] == 1
    assert "parent" not in seeds.to_dict()["segments"][0]


def test_version_1_files_may_repeat_a_segment_name():
    doc = {"segments": [EXAMPLE_SEEDS["segments"][0]] * 2}
    assert len(seeds_from_dict(doc).segments) == 2


def _tree_with(index: int, **changes) -> dict:
    doc = {**TREE, "segments": [dict(s) for s in TREE["segments"]]}
    doc["segments"][index].update(changes)
    doc["segments"][index] = {k: v for k, v in doc["segments"][index].items() if v is not None}
    return doc


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({**TREE, "version": 1}, "'parent' needs version 2"),
        (_tree_with(1, parent="LCX"), "parent 'LCX' is not the name of an earlier segment"),
        (_tree_with(1, parent="D1 distal"), "not the name of an earlier segment"),
        (_tree_with(1, parent="D1"), "not the name of an earlier segment"),  # itself
        (_tree_with(1, bifurcation="nowhere"), "'nowhere' is not the name of a feature"),
        (_tree_with(1, bifurcation=None), "needs both 'parent' and 'bifurcation'"),
        (_tree_with(1, parent=7), "a name (text)"),
        (_tree_with(2, name="D1"), "same name"),
    ],
)
def test_bad_trees_are_refused_in_one_line(doc, message):
    with pytest.raises(SeedsError) as info:
        seeds_from_dict(doc, source="tree.json")
    assert str(info.value).startswith("tree.json: segments[")
    assert message in str(info.value)
    assert "\n" not in str(info.value)
