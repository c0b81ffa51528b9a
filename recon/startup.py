"""What a `coronary3d` process sets before the numerical libraries load.

The pipeline's matrix products are small (profile tables of ~50 x 1000 by
~1000 x 60); OpenBLAS and OpenMP would run each on every core, and on a
machine whose cores are busy (other jobs, the benchmarks' worker processes)
the threads wait on one another: one such product took 0.13-0.33 s instead
of 0.3 ms on one thread (docs/benchmarks.md). The command line therefore
asks for one thread per process, unless the user set a count; worker
processes (the benchmarks' pool, Dask's workers) inherit the setting.
"""

from __future__ import annotations

import os
import sys

__all__ = ["THREAD_VARIABLES", "cap_math_threads"]

#: The thread-count variables of the BLAS and OpenMP runtimes numpy, scipy and cv2 use.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def cap_math_threads() -> bool:
    """Set each of :data:`THREAD_VARIABLES` the user left unset to 1, if numpy has not
    loaded yet (the runtimes read them once, when they load); returns whether it did."""
    if "numpy" in sys.modules:
        return False
    for name in THREAD_VARIABLES:
        os.environ.setdefault(name, "1")
    return True
