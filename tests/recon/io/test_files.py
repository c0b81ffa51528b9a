"""recon.io.files: the one JSON reader and the one atomic writer."""

import os
import stat

import pytest

from recon.errors import LoadError, OutputError
from recon.io.files import atomic_write_bytes, read_json


def test_read_json_errors_name_the_file(tmp_path):
    good = tmp_path / "good.json"
    good.write_text('{"a": [1, 2]}')
    assert read_json(good, LoadError) == {"a": [1, 2]}
    bad = tmp_path / "bad.json"
    bad.write_text("{nope")
    with pytest.raises(LoadError, match=r"bad\.json: not valid JSON \(line 1"):
        read_json(bad, LoadError)
    with pytest.raises(LoadError, match=r"absent\.json: cannot read the geometry JSON"):
        read_json(tmp_path / "absent.json", LoadError, "geometry JSON")


def test_atomic_write_makes_folders_and_the_usual_mode(tmp_path):
    path = tmp_path / "a" / "b" / "out.bin"
    atomic_write_bytes(path, b"one")
    atomic_write_bytes(path, b"two")
    assert path.read_bytes() == b"two"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask
    assert not list(path.parent.glob(".*tmp"))


def test_atomic_write_oserror_is_an_output_error_naming_the_path(tmp_path):
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    with pytest.raises(OutputError) as err:
        atomic_write_bytes(blocker / "out.bin", b"data")
    message = str(err.value)
    assert message.startswith(f"{blocker / 'out.bin'}: cannot write the file (")
    assert str(blocker) in message and "\n" not in message
    folder = tmp_path / "folder"
    (folder / "taken").mkdir(parents=True)
    with pytest.raises(OutputError, match=r"taken: cannot write the file"):
        atomic_write_bytes(folder / "taken", b"data")
    assert not list(folder.glob(".*tmp"))
