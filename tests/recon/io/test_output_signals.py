"""`coronary3d reconstruct` as a real process: signals while it writes, folders it must refuse."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from support import DEMO, assert_one_line_error, run_cli


def _start(out: Path, *extra: str) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k != "CORONARY3D_DEBUG"}
    return subprocess.Popen(
        [sys.executable, "-m", "recon.cli", "reconstruct", "--demo", "--out", str(out),
         "--quiet", *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )


def _temps(out: Path) -> list[str]:
    return sorted(p.name for p in out.glob(".*.tmp")) if out.exists() else []


def _signal_when_writing(proc: subprocess.Popen, out: Path, sig: int) -> bool:
    """Send ``sig`` as soon as a temporary output file appears; False if none was seen."""
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            names = [e.name for e in os.scandir(out)]
        except FileNotFoundError:
            continue
        if any(n.endswith(".tmp") and not n.startswith(".outputs.json") for n in names):
            proc.send_signal(sig)
            return True
    return False


def assert_complete_or_absent(out: Path) -> None:
    """The folder is absent, or holds exactly one complete set whose files match its manifest."""
    assert _temps(out) == []
    if not out.exists():
        return
    manifest = json.loads((out / "outputs.json").read_text())
    assert manifest["complete"] is True
    assert sorted(p.name for p in out.iterdir()) == sorted([*manifest["files"], "outputs.json"])
    for name, entry in manifest["files"].items():
        assert hashlib.sha256((out / name).read_bytes()).hexdigest() == entry["sha256"], name


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_while_writing_leaves_no_temporary_and_no_partial_set(
    tmp_path: Path, sig: int
) -> None:
    out = tmp_path / "out"
    proc = _start(out)
    seen = _signal_when_writing(proc, out, sig)
    _, stderr = proc.communicate(timeout=120)
    assert seen, f"no temporary file was ever seen (exit {proc.returncode}): {stderr}"
    assert proc.returncode in (128 + sig, 0), stderr  # 0: the signal came after the last rename
    assert "Traceback" not in stderr
    assert_complete_or_absent(out)


def test_sigterm_during_the_computation_writes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    env = {k: v for k, v in os.environ.items() if k != "CORONARY3D_DEBUG"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "recon.cli", "reconstruct", "--demo", "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )
    assert proc.stderr is not None
    first = proc.stderr.readline()  # the first progress line: tracing, long before the outputs
    assert "%]" in first, first
    proc.send_signal(signal.SIGTERM)
    _, rest = proc.communicate(timeout=120)
    stderr = first + rest
    assert proc.returncode == 128 + signal.SIGTERM, stderr
    assert "Traceback" not in stderr and not out.exists()


def test_after_a_sigkill_the_next_run_sweeps_the_temporaries(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = _start(out)
    assert _signal_when_writing(proc, out, signal.SIGKILL)
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    left = _temps(out)
    manifest = json.loads((out / "outputs.json").read_text())
    if left:  # killed before the renames: recognisably incomplete
        assert manifest["complete"] is False
    rerun = run_cli("reconstruct", "--demo", "--out", str(out), "--quiet")
    assert rerun.returncode == 0, rerun.stderr
    assert_complete_or_absent(out)


def test_a_seeds_file_at_out_report_json_is_never_replaced(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    seeds = out / "report.json"
    seeds.write_bytes((DEMO / "seeds.json").read_bytes())
    proc = run_cli("reconstruct", str(DEMO / "a.dcm"), str(DEMO / "b.dcm"), "--seeds",
                   str(seeds), "--out", str(out), "--quiet")
    assert_one_line_error(proc, str(seeds), "seeds file")
    assert seeds.read_bytes() == (DEMO / "seeds.json").read_bytes()
    assert sorted(p.name for p in out.iterdir()) == ["report.json"]


@pytest.mark.parametrize("where", ["", "   "])
def test_out_must_name_a_folder(tmp_path: Path, where: str) -> None:
    proc = run_cli("reconstruct", "--demo", "--out", where, cwd=tmp_path)
    assert_one_line_error(proc, "--out")
    assert not list(tmp_path.iterdir())


def test_a_folder_in_place_of_report_json_is_refused_before_any_work(tmp_path: Path) -> None:
    out = tmp_path / "out"
    (out / "report.json").mkdir(parents=True)
    proc = run_cli("reconstruct", "--demo", "--out", str(out))
    assert_one_line_error(proc, str(out / "report.json"), "is a folder")
    assert "tracing" not in proc.stderr  # refused before the reconstruction, not after
    assert sorted(p.name for p in out.iterdir()) == ["report.json"]


@pytest.mark.parametrize("when", ["just before the command", "as the handlers are put back"])
def test_a_signal_at_the_edges_of_the_command_is_an_exit_code_not_a_traceback(
    monkeypatch: pytest.MonkeyPatch, when: str
) -> None:
    """A SIGINT (raised by the handler, as it would be) in the instant after the handlers
    are installed or while they are put back after the command: exit 130, as during the
    command (a fuzz run saw a traceback from the second)."""
    from recon import cli
    from recon.io import output_set

    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)}
    monkeypatch.setitem(cli.COMMANDS, "info", lambda args: 0)
    if when == "just before the command":
        install = output_set.raise_on_termination

        def installed_then_signalled() -> None:
            install()
            raise output_set.Terminated(signal.SIGINT)

        monkeypatch.setattr(output_set, "raise_on_termination", installed_then_signalled)
    else:
        real, calls = signal.signal, []

        def put_back(sig: int, handler: object) -> object:
            calls.append(sig)
            if len(calls) == 3:  # the first one after raise_on_termination's two
                raise output_set.Terminated(signal.SIGINT)
            return real(sig, handler)

        monkeypatch.setattr(signal, "signal", put_back)
    try:
        assert cli.main(["info", str(DEMO / "a.dcm")]) == 128 + signal.SIGINT
    finally:
        monkeypatch.undo()
        for sig, handler in saved.items():
            signal.signal(sig, handler)
