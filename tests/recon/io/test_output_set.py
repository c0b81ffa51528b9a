"""Outputs as one set (recon.io.output_set): checks, manifest, clean-up, in-process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from recon.errors import OutputError
from recon.io.output_set import (
    MANIFEST_NAME,
    check_output_folder,
    read_manifest,
    write_file_set,
)

FILES = {"centerline.csv": b"s_mm\n0\n", "mesh.stl": b"x" * 5000, "report.json": b"{}\n"}
KNOWN = ("centerline.csv", "mesh.stl", "mesh.obj", "report.json")


def _listing(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir()}


def test_a_set_has_its_files_and_a_complete_manifest(tmp_path: Path) -> None:
    out = tmp_path / "new" / "out"
    paths = write_file_set(out, FILES, known=KNOWN, version="9")
    assert [p.name for p in paths] == list(FILES)
    assert sorted(_listing(out)) == sorted([*FILES, MANIFEST_NAME])
    manifest = read_manifest(out)
    assert manifest is not None and manifest["complete"] is True
    assert manifest["files"]["mesh.stl"]["bytes"] == 5000
    assert len(manifest["files"]["report.json"]["sha256"]) == 64


def test_a_rerun_replaces_the_earlier_set_whole(tmp_path: Path) -> None:
    write_file_set(tmp_path, {**FILES, "mesh.obj": b"o"}, known=KNOWN)
    write_file_set(tmp_path, FILES, known=KNOWN)
    # the earlier run's mesh.obj is not left beside the new set
    assert sorted(_listing(tmp_path)) == sorted([*FILES, MANIFEST_NAME])


@pytest.mark.parametrize("entry", ["notes.txt", "a.dcm", ".hidden"])
def test_a_folder_holding_other_files_is_refused(tmp_path: Path, entry: str) -> None:
    (tmp_path / entry).write_text("mine")
    with pytest.raises(OutputError, match="not a coronary3d output") as err:
        write_file_set(tmp_path, FILES, known=KNOWN)
    assert str(tmp_path) in str(err.value) and entry in str(err.value)
    assert _listing(tmp_path) == {entry: b"mine"}


def test_an_output_name_holding_someone_elses_file_is_refused(tmp_path: Path) -> None:
    (tmp_path / "report.json").write_text('{"version": 1, "segments": []}')
    with pytest.raises(OutputError, match="not a coronary3d output"):
        write_file_set(tmp_path, FILES, known=KNOWN)


def test_an_output_folder_from_before_manifests_is_accepted(tmp_path: Path) -> None:
    (tmp_path / "report.json").write_text('{"software": {"name": "coronary3d"}}')
    (tmp_path / "mesh.obj").write_text("old")
    write_file_set(tmp_path, FILES, known=KNOWN)
    assert (tmp_path / "report.json").read_bytes() == FILES["report.json"]


def test_an_output_never_replaces_an_input(tmp_path: Path) -> None:
    seeds = tmp_path / "report.json"
    seeds.write_text('{"software": {"name": "coronary3d"}}')  # even one that looks like ours
    with pytest.raises(OutputError, match="is the seeds file of this run") as err:
        check_output_folder(tmp_path, list(FILES), [("seeds file", seeds)], KNOWN)
    assert str(seeds) in str(err.value)
    hard = tmp_path / "elsewhere.json"
    os.link(seeds, hard)  # the same file under another name
    other = tmp_path / "out"
    other.mkdir()
    os.link(seeds, other / "report.json")
    with pytest.raises(OutputError, match="is the seeds file"):
        write_file_set(other, FILES, [("seeds file", hard)], KNOWN)
    assert seeds.read_text() == '{"software": {"name": "coronary3d"}}'


def test_the_out_folder_is_not_an_input_nor_a_file_nor_empty(tmp_path: Path) -> None:
    a = tmp_path / "a.dcm"
    a.write_bytes(b"dicom")
    with pytest.raises(OutputError, match="is a file, not a folder"):
        write_file_set(a, FILES, [("file A", a)])
    with pytest.raises(OutputError, match="--out is empty"):
        write_file_set("", FILES)
    assert a.read_bytes() == b"dicom"


def test_a_failed_write_leaves_the_earlier_set_complete(tmp_path: Path) -> None:
    write_file_set(tmp_path, FILES, known=KNOWN)
    before = _listing(tmp_path)
    huge = {**FILES, "mesh.stl": b"y" * 3_000_000}
    code = (
        "import resource, signal, sys\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (1_000_000, 1_000_000))\n"
        "from recon.io.output_set import write_file_set\n"
        "from recon.errors import OutputError\n"
        f"files = {{'centerline.csv': b'new', 'mesh.stl': b'y' * {len(huge['mesh.stl'])}, "
        "'report.json': b'{}'}\n"
        "try:\n"
        f"    write_file_set({str(tmp_path)!r}, files, known={KNOWN!r})\n"
        "except OutputError as exc:\n"
        "    print(exc)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    line = proc.stdout.strip()
    assert line.startswith(f"{tmp_path / 'mesh.stl'}: cannot write the file (File too large)")
    assert "\n" not in line
    assert _listing(tmp_path) == before  # the earlier set, its manifest complete, no temps


def test_a_failed_write_into_a_new_folder_leaves_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    code = (
        "import resource, signal\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, 100_000))\n"
        "from recon.io.output_set import write_file_set\n"
        "from recon.errors import OutputError\n"
        "try:\n"
        f"    write_file_set({str(out)!r}, {{'a.csv': b'1', 'mesh.stl': b'y' * 200_000}})\n"
        "except OutputError as exc:\n"
        "    print(exc)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert "mesh.stl: cannot write the file" in proc.stdout, proc.stderr
    assert not out.exists()


def test_a_killed_runs_temporaries_are_swept_by_the_next(tmp_path: Path) -> None:
    write_file_set(tmp_path, FILES, known=KNOWN)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    stale = [tmp_path / f".mesh.stl.{dead}.0a1b2c3d.tmp", tmp_path / ".report.json.k2j3h4g5.tmp"]
    for path in stale:
        path.write_bytes(b"half")
    live = tmp_path / f".mesh.stl.{os.getppid()}.0a1b2c3d.tmp"  # a process still running
    live.write_bytes(b"busy")
    write_file_set(tmp_path, FILES, known=KNOWN)
    assert not any(p.exists() for p in stale)
    assert live.exists()
    manifest = json.loads((tmp_path / MANIFEST_NAME).read_text())
    assert manifest["complete"] is True


def test_only_plain_names_are_written(tmp_path: Path) -> None:
    for bad in ("../x", "sub/x", ".x", MANIFEST_NAME):
        with pytest.raises(ValueError):
            write_file_set(tmp_path, {bad: b"1"})
    assert not list(tmp_path.iterdir())
