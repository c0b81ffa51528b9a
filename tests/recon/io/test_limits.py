"""Bounded work: a job past its memory or CPU-time limit ends in one line naming the limit."""

from __future__ import annotations

import resource
from pathlib import Path

import numpy as np
import pytest
from support import assert_one_line_error, run_cli

from recon.io.limits import CPU_BUDGET_S, MEMORY_BUDGET_BYTES, LimitError, job_limits, limits_for


def test_the_budgets_grow_with_the_image_and_can_be_set() -> None:
    demo = limits_for(512 * 512)
    assert demo.memory_bytes == MEMORY_BUDGET_BYTES and demo.cpu_s == CPU_BUDGET_S
    assert limits_for(100 * 100) == demo  # never below the demo's
    big = limits_for(1024 * 1024)
    assert big.memory_bytes == 4 * MEMORY_BUDGET_BYTES and big.cpu_s == 4 * CPU_BUDGET_S
    given = limits_for(1024 * 1024, memory_gb=0.5, cpu_s=0)
    assert given.memory_bytes == 2**29 and given.cpu_s is None


def test_an_allocation_past_the_memory_limit_is_a_limit_error() -> None:
    before = resource.getrlimit(resource.RLIMIT_DATA)
    with pytest.raises(LimitError, match=r"limit of 0\.1 GB \(--max-memory-gb"):
        with job_limits(limits_for(1, memory_gb=0.1, cpu_s=0), "the test"):
            np.ones(2**30 // 8 * 4)  # 4 GB
    assert resource.getrlimit(resource.RLIMIT_DATA) == before  # put back
    np.ones(2**27 // 8)  # 128 MB: fine again


def test_reconstruct_past_its_memory_limit_says_which(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = run_cli("reconstruct", "--demo", "--out", str(out), "--quiet", "--max-memory-gb",
                   "0.02")
    assert_one_line_error(proc, "--max-memory-gb", "memory")
    assert not out.exists()


def test_reconstruct_past_its_cpu_limit_says_which(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = run_cli("reconstruct", "--demo", "--out", str(out), "--quiet", "--max-cpu-s", "1")
    assert_one_line_error(proc, "--max-cpu-s", "CPU-time limit of 1 s")
    assert not out.exists()
