"""Bounded work: a job past its memory or CPU-time limit ends in one line naming the limit."""

from __future__ import annotations

import resource
import threading
import time
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
    # the demo's job takes ~0.4 s of CPU on a fast idle machine: 0.1 s is surely passed
    proc = run_cli("reconstruct", "--demo", "--out", str(out), "--quiet", "--max-cpu-s", "0.1")
    assert_one_line_error(proc, "--max-cpu-s", "CPU-time limit of 0.1 s")
    assert not out.exists()


def _cpu_s() -> float:
    """The process's CPU time (all threads) on the clock its CPU timers count
    (CLOCK_PROCESS_CPUTIME_ID; getrusage's sampled figure lagged it under load)."""
    return time.process_time()


def test_the_cpu_limit_holds_to_a_fraction_of_a_second() -> None:
    """RLIMIT_CPU counts whole seconds (1 s could let 2 s through); the timer does not."""
    start = _cpu_s()
    with pytest.raises(LimitError, match=r"CPU-time limit of 0\.3 s \(--max-cpu-s\)$"):
        with job_limits(limits_for(1, memory_gb=0, cpu_s=0.3), "the test"):
            a = np.random.default_rng(0).random((200, 200))
            while _cpu_s() - start < 5.0:
                a = np.tanh(a @ a.T / 200.0)
    spent = _cpu_s() - start
    threads = sorted(t.name for t in threading.enumerate())
    # the point is that 1 s no longer lets 2 s by; the lower bound says the limit did not
    # fire at once (a signal left over from elsewhere)
    assert 0.1 <= spent < 0.8, f"fired after {spent:.3f} s of CPU; threads alive: {threads}"
    time.sleep(0.05)
    with job_limits(limits_for(1, memory_gb=0, cpu_s=0.3), "the test"):
        pass  # a block that ends in time: no timer left behind
    t0 = _cpu_s()
    while _cpu_s() - t0 < 0.5:  # past the old budget, outside the block: nothing fires
        np.tanh(np.ones(10000))
