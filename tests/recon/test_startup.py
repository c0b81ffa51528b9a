"""recon.startup: one BLAS / OpenMP thread per coronary3d process unless the user says."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from recon.startup import THREAD_VARIABLES

_ROOT = Path(__file__).resolve().parents[2]


def _python(code: str, **env_extra: str) -> str:
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    env["PYTHONPATH"] = str(_ROOT)
    env.update(env_extra)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True, timeout=120)
    return out.stdout.strip()


def test_cap_sets_unset_variables_before_numpy_loads():
    code = ("import os\nfrom recon.startup import cap_math_threads, THREAD_VARIABLES\n"
            "done = cap_math_threads()\nimport numpy\n"
            "print(done, *[os.environ.get(v) for v in THREAD_VARIABLES])")
    assert _python(code) == "True 1 1 1"


def test_cap_keeps_the_users_count():
    code = ("import os\nfrom recon.startup import cap_math_threads\ncap_math_threads()\n"
            "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_NUM_THREADS'])")
    assert _python(code, OPENBLAS_NUM_THREADS="2") == "2 1"


def test_cap_does_nothing_once_numpy_is_loaded():
    code = ("import numpy, os\nfrom recon.startup import cap_math_threads\n"
            "print(cap_math_threads(), os.environ.get('OPENBLAS_NUM_THREADS'))")
    assert _python(code) == "False None"


def test_the_command_line_module_loads_no_numpy():
    """main() caps the threads only if importing recon.cli has not loaded numpy."""
    code = "import sys, recon.cli\nprint('numpy' in sys.modules)"
    assert _python(code) == "False"


def test_the_command_line_process_runs_with_one_thread(tmp_path):
    """A real `python -m recon.cli` process (its main() at __main__) leaves the cap in its
    environment, which the worker processes it starts inherit."""
    probe = tmp_path / "probe.py"
    probe.write_text(
        "import atexit, os, runpy, sys\n"
        "sys.argv = ['coronary3d', '--help']\n"
        "atexit.register(lambda: print('threads', os.environ.get('OPENBLAS_NUM_THREADS')))\n"
        "runpy.run_module('recon.cli', run_name='__main__', alter_sys=True)\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    env["PYTHONPATH"] = str(_ROOT)
    out = subprocess.run([sys.executable, str(probe)], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "threads 1"
