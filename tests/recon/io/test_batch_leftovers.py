"""`coronary3d batch` after a SIGKILL: the next run sweeps what the killed one left, and two
batches never write into one folder at once. Real processes, real SIGKILL."""

from __future__ import annotations

import csv
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from support import DEMO, assert_one_line_error, run_cli

from recon.io.batch import CASE_RECORD, batch_lock, sweep_leftovers

_WRITER = """
import sys
from pathlib import Path
from recon.io.batch import failed_record, write_case_folder
write_case_folder(Path(sys.argv[1]), "case00", {"mesh.stl": bytes(1 << 28)},
                  failed_record("case00", "a large case"))
"""


def _manifest(folder: Path, n: int) -> Path:
    inputs = folder / "inputs"
    inputs.mkdir(parents=True)
    for name in ("a.dcm", "b.dcm", "seeds.json"):
        shutil.copy(DEMO / name, inputs / name)
    lines = ["id,a,b,seeds"] + [f"case{k:02d},inputs/a.dcm,inputs/b.dcm,inputs/seeds.json"
                                for k in range(n)]
    path = folder / "manifest.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def _hidden(out: Path) -> list[str]:
    return sorted(p.name for p in out.iterdir() if p.name.startswith("."))


def _wait_for(predicate, what: str, proc: subprocess.Popen, timeout_s: float = 240.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert proc.poll() is None, f"the process ended before {what}"
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.001)


def test_a_case_writer_killed_midway_is_swept_by_the_next_batch(tmp_path: Path) -> None:
    manifest = _manifest(tmp_path, 1)
    out = tmp_path / "out"
    out.mkdir()
    proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(out)])
    try:
        def writing() -> list[Path]:
            return [p for p in out.glob(".case00.tmp-*") if any(p.iterdir())]

        _wait_for(lambda: bool(writing()), "a case folder being written", proc)
        proc.send_signal(signal.SIGSTOP)
        tmp = writing()[0]
        assert sweep_leftovers(out, ["case00"]) == []  # its writer is alive: left alone
        proc.kill()  # SIGKILL
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert tmp.is_dir() and not (out / "case00").exists()  # what a SIGKILL leaves
    (out / ".case00.tmp-otherhost-4242-0123abcd").mkdir()  # a lost node's worker
    (out / ".case00.k3j2h1g0").mkdir()  # the temporary name of earlier versions
    (out / ".results.csv.x1y2z3.tmp").write_text("id,st")  # the table, killed midway
    (out / ".keep").mkdir()  # not ours: never touched
    (out / ".other.k3j2h1g0").mkdir()  # an old-style name of a case not in the manifest

    proc2 = run_cli("batch", str(manifest), "--out", str(out))
    assert proc2.returncode == 0, proc2.stderr
    assert "0 already recorded, 1 to run" in proc2.stderr
    assert "; 4 left by a killed run removed" in proc2.stderr
    assert _hidden(out) == [".keep", ".other.k3j2h1g0"]
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [(r["id"], r["status"]) for r in rows] == [("case00", "done")]
    assert (out / "case00" / CASE_RECORD).is_file()


def _group(pgid: int) -> list[int]:
    """The processes still in process group ``pgid``."""
    found = []
    for entry in os.scandir("/proc"):
        if entry.name.isdigit():
            try:
                if os.getpgid(int(entry.name)) == pgid:
                    found.append(int(entry.name))
            except (ProcessLookupError, PermissionError):
                pass
    return found


def test_a_batch_killed_with_its_workers_is_finished_by_the_next_run(tmp_path: Path) -> None:
    manifest = _manifest(tmp_path, 3)
    out = tmp_path / "out"
    env = {k: v for k, v in os.environ.items() if k != "CORONARY3D_DEBUG"}
    proc = subprocess.Popen([sys.executable, "-m", "recon.cli", "batch", str(manifest),
                             "--out", str(out), "--quiet"], env=env, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        # the first case recorded; the second is being computed or written
        _wait_for(lambda: (out / "case00" / CASE_RECORD).exists(), "the first case", proc)
        os.killpg(proc.pid, signal.SIGKILL)  # the batch, its cluster, its workers, their cases
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    deadline = time.monotonic() + 10
    while _group(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _group(proc.pid) == []  # nothing of the killed batch runs on
    assert not (out / "results.csv").exists()

    again = run_cli("batch", str(manifest), "--out", str(out))
    assert again.returncode == 0, again.stderr
    assert "1 already recorded" in again.stderr  # case00 is not redone
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [(r["id"], r["status"]) for r in rows] == [(f"case{k:02d}", "done") for k in range(3)]
    assert _hidden(out) == []


def test_a_second_batch_into_a_folder_in_use_is_refused(tmp_path: Path) -> None:
    manifest = _manifest(tmp_path, 1)
    out = tmp_path / "out"
    with batch_lock(out):
        proc = run_cli("batch", str(manifest), "--out", str(out), "--quiet")
    assert_one_line_error(proc, str(out), "another coronary3d batch is writing into this folder")
    assert sorted(out.iterdir()) == []
    (tmp_path / "file").write_text("x")
    proc = run_cli("batch", str(manifest), "--out", str(tmp_path / "file"), "--quiet")
    assert_one_line_error(proc, str(tmp_path / "file"), "cannot use the batch folder")
