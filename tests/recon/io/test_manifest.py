"""recon.io.manifest: the batch manifest, its paths and every way it can be wrong."""

from __future__ import annotations

import pytest

from recon.io.manifest import ManifestError, read_manifest


def _write(tmp_path, text: str):
    path = tmp_path / "cases" / "manifest.csv"
    path.parent.mkdir(exist_ok=True)
    path.write_text(text)
    return path


def test_paths_are_relative_to_the_manifest_and_options_are_parsed(tmp_path):
    path = _write(
        tmp_path,
        "id,a,b,seeds,frame_a,geometry_b,matcher,self_calibration\n"
        "p01,a.dcm,sub/b.dcm,/abs/seeds.json,3,geo.json,match2,yes\n"
        "p02,a.dcm,b.dcm,seeds.json,,,,\n"
        "\n",
    )
    first, second = read_manifest(path)
    base = path.parent.resolve()
    assert (first.id, first.a, first.b, first.seeds) == (
        "p01", str(base / "a.dcm"), str(base / "sub" / "b.dcm"), "/abs/seeds.json"
    )
    assert first.options == {
        "frame_a": 3, "geometry_b": str(base / "geo.json"), "matcher": "match2",
        "self_calibration": True,
    }
    assert second.options == {} and second.line == 3


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("", "empty manifest"),
        ("id,a,b\nx,1,2\n", "line 1: the header must start with id,a,b,seeds"),
        ("id,a,b,seeds,colour\n", "line 1: unknown column 'colour'"),
        ("id,a,b,seeds,segment,segment\n", "column 'segment' appears twice"),
        ("id,a,b,seeds\n", "no cases"),
        ("id,a,b,seeds\nx,a,b\n", "line 2: 3 cells, the header has 4"),
        ("id,a,b,seeds\n../up,a,b,s\n", "line 2: id '../up' is not a folder name"),
        ("id,a,b,seeds\n.hidden,a,b,s\n", "id '.hidden' is not a folder name"),
        ("id,a,b,seeds\nx,a,b,s\ny,a,b,s\nx,a,b,s\n", "line 4: id 'x' is already on line 2"),
        ("id,a,b,seeds\nx,a,,s\n", "line 2: the b cell is empty"),
        ("id,a,b,seeds,frame_a\nx,a,b,s,two\n", "line 2: frame_a 'two' is not an integer"),
        ("id,a,b,seeds,optimizer\nx,a,b,s,adam\n", "optimizer 'adam' is not one of palm, lm"),
        ("id,a,b,seeds,self_calibration\nx,a,b,s,maybe\n", "'maybe' is not one of 1, true"),
    ],
)
def test_a_bad_manifest_is_one_line_naming_it(tmp_path, text, fragment):
    path = _write(tmp_path, text)
    with pytest.raises(ManifestError) as err:
        read_manifest(path)
    message = str(err.value)
    assert message.startswith(str(path)) and fragment in message and "\n" not in message


def test_a_missing_manifest(tmp_path):
    with pytest.raises(ManifestError, match=r"nope\.csv: cannot read the manifest"):
        read_manifest(tmp_path / "nope.csv")


def test_a_named_pipe_or_a_huge_file_is_refused_without_reading_it(tmp_path):
    import os

    from support import assert_one_line_error, run_cli

    fifo = tmp_path / "manifest.csv"
    os.mkfifo(fifo)  # reading it would wait for a writer forever
    proc = run_cli("batch", str(fifo), "--out", str(tmp_path / "out"))
    assert_one_line_error(proc, str(fifo), "the manifest is not a regular file")
    assert not (tmp_path / "out").exists()
    big = tmp_path / "big.csv"
    with big.open("wb") as fh:
        fh.truncate(65 * 2**20)  # sparse: 65 MB that take no disk
    with pytest.raises(ManifestError, match=r"big\.csv: the manifest is 68\.2 MB; at most 64 MB"):
        read_manifest(big)
