"""What the job's start-up imports: no scipy.signal/scipy.stats, pydicom's download helpers
deferred until used (and then the real modules)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)


def test_the_reconstruct_command_imports_no_scipy_signal_nor_stats() -> None:
    code = (
        "import sys; import recon.cli, recon.pipeline, recon.io.angiogram, recon.io.outputs, "
        "recon.io.seeds_file; "
        "heavy = {'scipy.signal', 'scipy.stats'} & set(sys.modules); assert not heavy, heavy"
    )
    result = _run(code)
    assert result.returncode == 0, result.stderr


def test_requests_and_tqdm_wait_for_their_first_use_and_then_are_the_real_modules() -> None:
    code = "\n".join([
        "import sys, recon.io.angiogram, pydicom.data.download as dl",
        "from recon import DEFERRED_MODULES",
        "assert set(DEFERRED_MODULES) == {'requests', 'tqdm'}",
        "for name in DEFERRED_MODULES:",
        "    assert type(sys.modules[name]).__name__ == '_DeferredModule', name",
        "assert 'urllib3' not in sys.modules",
        "assert dl.HAVE_REQUESTS and dl.USE_PROGRESS_BAR",
        "import requests, tqdm",
        "assert callable(requests.get) and callable(dl.requests.Session)",
        "assert type(sys.modules['requests']).__name__ == 'module'",
        "assert sys.modules['requests'].__file__.endswith('__init__.py')",
        "assert 'urllib3' in sys.modules",
        "from tqdm import tqdm as bar",
        "assert bar is dl.tqdm.tqdm",
    ])
    result = _run(code)
    assert result.returncode == 0, result.stderr


def test_the_package_still_re_exports_its_api_on_first_use() -> None:
    import recon
    from recon.geometry import ViewGeometry

    assert recon.ViewGeometry is ViewGeometry
    for name in recon.__all__:
        assert getattr(recon, name) is not None, name
