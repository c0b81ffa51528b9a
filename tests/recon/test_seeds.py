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
        ({"version": 2}, "unsupported version"),
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
