"""recon.io.seeds_file: reading and writing seeds.json."""

import json

import pytest
from support import EXAMPLE_SEEDS

from recon.errors import OutputError
from recon.io.seeds_file import load_seeds, save_seeds
from recon.seeds import SeedsError, seeds_from_dict


def write(tmp_path, data, name="seeds.json"):
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


def test_reads_the_documented_example(tmp_path):
    assert load_seeds(write(tmp_path, EXAMPLE_SEEDS)) == seeds_from_dict(EXAMPLE_SEEDS)


def test_version_is_optional_and_round_trip(tmp_path):
    data = dict(EXAMPLE_SEEDS)
    data.pop("version")
    seeds = load_seeds(write(tmp_path, data))
    out = tmp_path / "sub" / "again.json"
    save_seeds(seeds, out)
    assert load_seeds(out) == seeds
    assert json.loads(out.read_text())["version"] == 1
    assert not list(out.parent.glob("*.tmp"))


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ("{not json", "not valid JSON"),
        ([1, 2], "top level"),
        ({"version": 3}, "unsupported version"),
        ({"segments": [{"a": [[1, 2]], "b": [[1, 2], [3, 4]]}]}, "at least two points"),
        ({"segments": [{"a": [[1, "x"], [3, 4]], "b": [[1, 2], [3, 4]]}]}, "segments[0].a[0]"),
        ({"features": [{"a": [1, 2]}]}, "features[0]"),
        ({"features": [{"a": [1, 2], "b": [float("nan"), 1]}]}, "features[0].b"),
    ],
)
def test_bad_files_name_the_file_and_the_entry(tmp_path, data, message):
    path = write(tmp_path, data if isinstance(data, str) else json.dumps(data))
    with pytest.raises(SeedsError) as info:
        load_seeds(path)
    assert str(path) in str(info.value)
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(SeedsError, match="cannot read"):
        load_seeds(tmp_path / "nope.json")


def test_unwritable_path_is_an_output_error(tmp_path):
    seeds = load_seeds(write(tmp_path, EXAMPLE_SEEDS))
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(OutputError) as info:
        save_seeds(seeds, blocker / "seeds.json")
    assert str(blocker / "seeds.json") in str(info.value)
    assert "\n" not in str(info.value)
