"""Generated bad inputs (tests/fuzz_cases.py) through the CLI: one line, exit 2, no traceback."""

from __future__ import annotations

import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
from fuzz_cases import FuzzCase, failure, make_cases, output_folder, run_in_process
from support import DEMO, assert_one_line_error, run_cli


@pytest.fixture(scope="module")
def cases(tmp_path_factory: pytest.TempPathFactory) -> list[FuzzCase]:
    return make_cases(tmp_path_factory.mktemp("fuzz"), n_random=200, seed=17)


def test_every_generated_bad_input_is_refused_in_one_line(cases: list[FuzzCase]) -> None:
    families = Counter(case.family for case in cases)
    assert len(cases) >= 300 and len(families) >= 10
    failures = []
    for case in cases:
        reason = failure(case, run_in_process(case))
        if reason:
            failures.append(f"{case.family} / {case.label}: {reason}")
    assert not failures, f"{len(failures)} of {len(cases)}:\n" + "\n".join(failures[:20])


def test_the_check_itself_fails_on_a_traceback_or_a_success(tmp_path: Path) -> None:
    good = FuzzCase("control", "a valid info", ("info", str(DEMO / "a.dcm")))
    assert failure(good, run_in_process(good)) == "exit 0"
    out = tmp_path / "out"
    written = FuzzCase("control", "phantom", ("phantom", "--out", str(out)))
    assert failure(written, run_in_process(written)) == "exit 0"
    assert output_folder(written) == out and out.exists()


@pytest.mark.parametrize("label", [
    "DistanceSourceToDetector=1e308", "RepresentativeFrameNumber=[1,2]", "5000-digit integer",
    "/dev/zero as the seeds file", "phantom --stenosis nan", "reconstruct --bogus",
])
def test_a_handful_as_real_processes(cases: list[FuzzCase], label: str) -> None:
    (case,) = [c for c in cases if c.label == label]
    proc = run_cli(*case.argv)
    assert_one_line_error(proc, case.names)
    assert len([line for line in proc.stderr.splitlines() if line.strip()]) == 1, proc.stderr
    folder = output_folder(case)
    assert folder is None or not folder.exists()


def test_a_named_pipe_is_refused_at_once(tmp_path: Path) -> None:
    fifo = tmp_path / "a.dcm"
    os.mkfifo(fifo)
    proc = run_cli("info", str(fifo))
    assert_one_line_error(proc, str(fifo), "not a regular file")


def test_a_closed_stdout_ends_quietly() -> None:
    files = [str(DEMO / "a.dcm"), str(DEMO / "b.dcm")] * 20
    env = {k: v for k, v in os.environ.items() if k != "CORONARY3D_DEBUG"}
    proc = subprocess.Popen([sys.executable, "-m", "recon.cli", "info", *files],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.read(10)
    proc.stdout.close()  # as `| head -c 10` does, while more descriptions are to come
    stderr = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0
    assert stderr == "", stderr
