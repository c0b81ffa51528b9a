"""What `lint-imports` (the contracts in pyproject.toml) cannot see: importing the pipeline
loads no edge library at run time, even through a third-party package; no module is too long.

The layout's import rules themselves (layers, edge libraries, no viewer in recon, no
circles) are import-linter contracts, checked by `lint-imports` in .ci/run.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MAX_LINES = 700


def _py_files(*folders: str) -> list[Path]:
    return sorted(p for folder in folders for p in (ROOT / folder).rglob("*.py"))


def _rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


# Libraries that touch files, DICOM or a cluster: imported in recon/io/ only.
_EDGE_ONLY = ("pydicom", "highdicom", "vtk", "vtkmodules", "dask", "distributed")


def test_importing_the_pipeline_loads_no_edge_library_nor_viser() -> None:
    code = (
        "import recon.pipeline, sys; "
        f"loaded = {{*{_EDGE_ONLY!r}, 'viser'}} & set(sys.modules); assert not loaded, loaded"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("path", _py_files("recon", "viewer_app"), ids=_rel)
def test_no_module_is_over_700_lines(path: Path) -> None:
    n_lines = len(path.read_text(encoding="utf-8").splitlines())
    assert n_lines <= MAX_LINES, f"{_rel(path)} has {n_lines} lines (at most {MAX_LINES})"
