"""Bounded work: the memory and CPU time one reconstruction may use.

The inputs are bounded at the edge (file sizes, image size, seeds counts:
:mod:`recon.io.validate`, :mod:`recon.io.files`); these limits are the
backstop for what those bounds still let through. A job on a demo-sized pair
(512 x 512 px per view) may use :data:`MEMORY_BUDGET_BYTES` of data memory
and :data:`CPU_BUDGET_S` of CPU time (all threads); larger images get budgets
in proportion to their pixel count. The demo job itself uses about 0.36 GB
and 8 s of CPU.

:func:`job_limits` applies them to the process (``RLIMIT_DATA`` and
``RLIMIT_CPU`` soft limits, restored afterwards) and turns reaching one into
a :class:`LimitError` whose one line says which limit and its option. Native
code can be caught at the limit where Python cannot raise (OpenBLAS retries a
failed buffer allocation in a loop): with ``hard_exit`` (a real command-line
process, which has written no output yet) a watchdog thread then prints the
same line and ends the process with exit code 2.
"""

from __future__ import annotations

import contextlib
import resource
import signal
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from types import FrameType

from recon.errors import CoronaryError

__all__ = ["LimitError", "JobLimits", "limits_for", "job_limits", "MEMORY_BUDGET_BYTES",
           "CPU_BUDGET_S"]

MEMORY_BUDGET_BYTES = int(1.5 * 2**30)
CPU_BUDGET_S = 60.0
DEMO_PIXELS = 512 * 512  # per view


class LimitError(CoronaryError):
    """The job reached its memory or CPU-time limit; the line names the limit."""


@dataclass(frozen=True)
class JobLimits:
    """Limits of one job: data memory in bytes and CPU time in seconds (None: no limit)."""

    memory_bytes: int | None
    cpu_s: float | None

    def describe_memory(self) -> str:
        return f"{(self.memory_bytes or 0) / 2**30:.3g} GB"


def limits_for(pixels_per_view: int, memory_gb: float | None = None,
               cpu_s: float | None = None) -> JobLimits:
    """The default limits for views of ``pixels_per_view`` pixels (the larger view), or the
    ones given (``memory_gb`` / ``cpu_s``; 0 means no limit)."""
    scale = max(1.0, pixels_per_view / DEMO_PIXELS)
    memory = int(MEMORY_BUDGET_BYTES * scale) if memory_gb is None else int(memory_gb * 2**30)
    seconds = CPU_BUDGET_S * scale if cpu_s is None else float(cpu_s)
    return JobLimits(memory or None, seconds or None)


class _CpuLimitReached(BaseException):
    """Raised by the SIGXCPU handler; becomes a LimitError where it can be told apart."""


def _memory_message(what: str, limits: JobLimits) -> str:
    return (f"{what} needed more memory than its limit of {limits.describe_memory()} "
            "(--max-memory-gb; the inputs are too large or too many)")


def _cpu_message(what: str, limits: JobLimits) -> str:
    return f"{what} used more than its CPU-time limit of {limits.cpu_s:g} s (--max-cpu-s)"


def _watchdog(limits: JobLimits, what: str, data_cap: int | None, cpu_cap: float | None,
              done: threading.Event) -> None:
    """End the process (exit 2, one line) when the main thread is stuck at a limit."""
    import os
    import sys

    at_cap_since = None
    while not done.wait(0.2):
        now = time.monotonic()
        if data_cap is not None and _data_bytes_now() >= 0.98 * data_cap:
            at_cap_since = at_cap_since or now
        else:
            at_cap_since = None
        usage = resource.getrusage(resource.RUSAGE_SELF)
        over_cpu = cpu_cap is not None and usage.ru_utime + usage.ru_stime > cpu_cap + 10.0
        if (at_cap_since is not None and now - at_cap_since > 3.0) or over_cpu:
            message = _cpu_message(what, limits) if over_cpu else _memory_message(what, limits)
            with contextlib.suppress(Exception):
                sys.stderr.write(f"coronary3d: error: {message}\n")
                sys.stderr.flush()
            os._exit(2)


@contextlib.contextmanager
def job_limits(limits: JobLimits, what: str = "the reconstruction",
               hard_exit: bool = False) -> Iterator[None]:
    """Run the block under ``limits``; reaching one raises :class:`LimitError`.

    ``RLIMIT_DATA`` counts the process's heap and private mappings (numpy's
    arrays), so an allocation past it fails as a MemoryError; a profiling
    timer (``ITIMER_PROF``) sends SIGPROF when the process's CPU time (all
    threads) passes the budget, to the fraction of a second, and
    ``RLIMIT_CPU`` (whole seconds, SIGXCPU) is the backstop. The soft limits
    and the timer are put back when the block ends. Only the main thread can take
    the signal; elsewhere the CPU limit is not applied.
    """
    old_data = resource.getrlimit(resource.RLIMIT_DATA)
    old_cpu = resource.getrlimit(resource.RLIMIT_CPU)
    old_handler: object = None
    old_prof: object = None
    installed = False
    fired = False
    data_cap: int | None = None
    cpu_cap: float | None = None

    def on_xcpu(signum: int, frame: FrameType | None) -> None:
        nonlocal fired
        if not fired:
            fired = True
            raise _CpuLimitReached()

    if limits.memory_bytes is not None:
        _warm_blas()
        used = _data_bytes_now()
        cap = old_data[1]
        soft = limits.memory_bytes + used
        if cap != resource.RLIM_INFINITY:
            soft = min(soft, cap)
        resource.setrlimit(resource.RLIMIT_DATA, (soft, old_data[1]))
        data_cap = soft
    if limits.cpu_s is not None:
        with contextlib.suppress(ValueError):  # not the main thread
            old_handler = signal.signal(signal.SIGXCPU, on_xcpu)
            old_prof = signal.signal(signal.SIGPROF, on_xcpu)
            installed = True
        if installed:
            # the exact budget: SIGPROF after cpu_s of the process's CPU time (all threads);
            # RLIMIT_CPU (whole seconds) is the backstop
            signal.setitimer(signal.ITIMER_PROF, limits.cpu_s)
            usage = resource.getrusage(resource.RUSAGE_SELF)
            spent = usage.ru_utime + usage.ru_stime
            # one second more than the budget's whole seconds: getrusage's figure can lag
            # the kernel's CPU clock by tenths of a second under load, and the backstop
            # must not fire before the timer
            soft_cpu = int(spent + limits.cpu_s) + 2
            if old_cpu[1] != resource.RLIM_INFINITY:
                soft_cpu = min(soft_cpu, old_cpu[1])
            resource.setrlimit(resource.RLIMIT_CPU, (soft_cpu, old_cpu[1]))
            cpu_cap = float(soft_cpu)
    done = threading.Event()
    if hard_exit and (data_cap is not None or cpu_cap is not None):
        threading.Thread(target=_watchdog, args=(limits, what, data_cap, cpu_cap, done),
                         daemon=True, name="coronary3d-limits").start()
    try:
        yield
    except MemoryError:
        if limits.memory_bytes is None:
            raise
        raise LimitError(_memory_message(what, limits)) from None
    except _CpuLimitReached:
        raise LimitError(_cpu_message(what, limits)) from None
    except Exception as exc:  # a native library's own out-of-memory error (OpenCV's)
        if limits.memory_bytes is None or not _allocation_failed(exc):
            raise
        raise LimitError(_memory_message(what, limits)) from None
    finally:
        fired = True  # a timer that fires now, as the block ends, raises nothing
        done.set()
        resource.setrlimit(resource.RLIMIT_DATA, old_data)
        if installed:
            signal.setitimer(signal.ITIMER_PROF, 0)
            signal.signal(signal.SIGPROF, old_prof if old_prof is not None  # type: ignore
                          else signal.SIG_DFL)
            resource.setrlimit(resource.RLIMIT_CPU, old_cpu)
            signal.signal(signal.SIGXCPU, old_handler if old_handler is not None  # type: ignore
                          else signal.SIG_DFL)


def _allocation_failed(exc: Exception) -> bool:
    """True for an error a native library raises when an allocation fails (OpenCV's
    ``cv2.error`` "Insufficient memory", a C++ ``std::bad_alloc``)."""
    text = str(exc)
    return any(s in text for s in ("Insufficient memory", "Failed to allocate", "bad_alloc"))


def _warm_blas() -> None:
    """Let OpenBLAS make its per-thread buffers now: past the limit it aborts the process
    instead of raising MemoryError."""
    import numpy as np

    a = np.ones((512, 512))
    float((a @ a).sum() + np.linalg.solve(a + 512 * np.eye(512), a[:, 0]).sum())


def _data_bytes_now() -> int:
    """The process's data memory now (VmData, bytes); 0 when /proc does not say."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmData:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError):
        pass
    return 0
